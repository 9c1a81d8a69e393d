"""The steps of generated encoders and decoders: one small class per kind of step.

The codec planner (`codec.py`) turns the members of a type, or the arguments of an operation,
into a list of these; `templates/idl/_codec.j2` has one macro per class (named by `macro`) that
lays it out as code. Encoders append to `_buf`, a bytearray that starts with the 4-byte
encapsulation header; decoders read `_data` from `_off` with endianness index `_e`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar


@dataclass
class EncodeStep:
    macro: ClassVar[str]


@dataclass
class DecodeStep:
    macro: ClassVar[str]


@dataclass
class Bounded:
    """A step on a sequence or string with an optional bound."""

    bound: int | None

    @property
    def bound_expr(self) -> str:
        return "None" if self.bound is None else str(self.bound)


@dataclass
class Aligned:
    """A step on a run of fixed-size values, aligned to its first value's size."""

    align: int

    @property
    def padded(self) -> bool:
        return self.align > 1

    @property
    def align_mask(self) -> int:
        return self.align - 1


# ---- encoding ------------------------------------------------------------------------------


@dataclass
class PackCheck:
    """A packed value, for naming the one that does not fit (`_cdr.pack_error`)."""

    what: str  # Miro::Struct.member
    format: str  # its struct format ("h", "3i")
    values: str  # the expression of its wire values
    late_bound: bool  # it uses a loop variable (ruff's B023 does not apply: called at once)


@dataclass
class Pack(EncodeStep, Aligned):
    """A run of fixed-size values packed with one module-level Struct (`_P<codec>`)."""

    macro = "pack"

    codec: str
    values: list[str]
    checks: list[PackCheck]


@dataclass
class PutBounded(EncodeStep, Bounded):
    """`_cdr.<function>(_buf, value, bound, what)`."""

    macro = "put_bounded"
    function: ClassVar[str]

    expr: str
    what: str


class PutString(PutBounded):
    function = "_cdr.put_string"


class PutWString(PutBounded):
    function = "_cdr.put_wstring"


class PutOctets(PutBounded):
    function = "_cdr.put_octets"


class PutBooleans(PutBounded):
    function = "_cdr.put_booleans"


class PutChars(PutBounded):
    function = "_cdr.put_chars"


@dataclass
class PutNumbers(EncodeStep, Bounded):
    """A sequence of one numeric primitive (an `array.array` or any buffer), in bulk."""

    macro = "put_numbers"

    expr: str
    code: str  # array type code
    size: int
    what: str


@dataclass
class PutNumberArray(EncodeStep):
    """An array of numbers too long to pack with the values around it, in bulk."""

    macro = "put_number_array"

    expr: str
    code: str  # array type code
    size: int
    count: int
    what: str


@dataclass
class PutEnums(EncodeStep, Bounded):
    """A sequence of enumerators, checked against the enum's ordinals (`table`)."""

    macro = "put_enums"

    expr: str
    table: str
    what: str


@dataclass
class PutFlat(EncodeStep, Bounded):
    """A sequence of structs whose members are all one numeric primitive, in bulk."""

    macro = "put_flat"

    expr: str
    getter: str  # the module's attrgetter of the members
    count: int  # members per element
    code: str
    size: int
    what: str


@dataclass
class PutObject(EncodeStep):
    macro = "put_object"

    expr: str
    what: str


@dataclass
class EncodeNested(EncodeStep):
    """A struct, union or exception, by its `_enc_` function."""

    macro = "encode_nested"

    expr: str
    function: str
    what: str


@dataclass
class PutSequence(EncodeStep, Bounded):
    """The length, then each element (`var`) by `body`."""

    macro = "put_sequence"

    expr: str
    what: str
    var: str
    body: list[EncodeStep]


@dataclass
class PutArray(EncodeStep):
    """A length check, then each element (`var`) by `body`."""

    macro = "put_array"

    expr: str
    count: int
    what: str
    var: str
    body: list[EncodeStep]


@dataclass
class EncodeCase:
    labels: list[str]
    body: list[EncodeStep]


@dataclass
class EncodeBranches(EncodeStep):
    """A union's value by the branch its discriminator selects."""

    macro = "encode_branches"

    expr: str
    cases: list[EncodeCase]
    default: list[EncodeStep]  # the default branch (empty: there is none)
    what: str


# ---- decoding ------------------------------------------------------------------------------


@dataclass
class Unpack(DecodeStep, Aligned):
    """A run of fixed-size values unpacked into the tuple `var`."""

    macro = "unpack"

    var: str
    codec: str
    size: int
    count: int  # values in the tuple


@dataclass
class Assign(DecodeStep):
    macro = "assign"

    var: str
    expr: str
    annotation: str = ""


@dataclass
class GetBounded(DecodeStep, Bounded):
    """`var, _off = _cdr.<function>(_data, _off, _e, bound, what)`."""

    macro = "get_bounded"
    function: ClassVar[str]

    var: str
    what: str


class GetString(GetBounded):
    function = "_cdr.get_string"


class GetWString(GetBounded):
    function = "_cdr.get_wstring"


class GetOctets(GetBounded):
    function = "_cdr.get_octets"


class GetBooleans(GetBounded):
    function = "_cdr.get_booleans"


class GetChars(GetBounded):
    function = "_cdr.get_chars"


@dataclass
class GetNumbers(DecodeStep, Bounded):
    """A sequence of one numeric primitive, as an `array.array`."""

    macro = "get_numbers"

    var: str
    code: str
    size: int
    what: str


@dataclass
class GetNumberArray(DecodeStep):
    """An array of numbers too long to pack, as an `array.array`."""

    macro = "get_number_array"

    var: str
    code: str
    size: int
    count: int
    what: str


@dataclass
class GetEnums(DecodeStep, Bounded):
    """A sequence of enumerators, checked against the enum's members by ordinal (`table`)."""

    macro = "get_enums"

    var: str
    table: str
    what: str


@dataclass
class GetFlat(DecodeStep, Bounded):
    macro = "get_flat"

    var: str
    cls: str  # the element's class
    count: int
    code: str
    size: int
    what: str


@dataclass
class GetObject(DecodeStep):
    macro = "get_object"

    var: str
    what: str


@dataclass
class DecodeNested(DecodeStep):
    """A struct, union or exception, by its `_dec_` function."""

    macro = "decode_nested"

    var: str
    function: str


@dataclass
class GetSequence(DecodeStep, Bounded):
    """The length (`_n<counter>`, checked against the bytes left), then each element."""

    macro = "get_sequence"

    var: str
    min_size: int  # the fewest bytes an element takes
    what: str
    item: str  # the variable each element is decoded into
    counter: int
    body: list[DecodeStep]


@dataclass
class GetArray(DecodeStep):
    macro = "get_array"

    var: str
    count: int
    item: str
    body: list[DecodeStep]


@dataclass
class DecodeCase:
    labels: list[str]
    body: list[DecodeStep]


@dataclass
class DecodeBranches(DecodeStep):
    """A union's value (into `_x`) by the branch the discriminator `_d` selects."""

    macro = "decode_branches"

    cases: list[DecodeCase]
    default: list[DecodeStep]
