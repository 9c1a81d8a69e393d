"""The base classes of generated data types: `IdlType` (every struct, union and exception:
its IDL identity, data schema and type hash, registered in miro_gen.runtime.registry as it is
defined) and `IdlUnion` (discriminator, value, one property per branch), and the discriminator
a union's default branch gets. Generated code reaches them as `_cdr.IdlType`, `_cdr.IdlUnion`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any, ClassVar, Self

from miro_gen.runtime import registry

if TYPE_CHECKING:
    from miro_gen.runtime.cdr import Encoder


# ---- generated data types ----------------------------------------------------------------------


class IdlType:
    """What every generated struct, union and exception carries: its IDL identity, its data
    schema (the flattened IDL text of the type, for logs and tools) and the schema's hash."""

    __slots__ = ()

    _repo_id: ClassVar[str] = ""
    _type_name: ClassVar[str] = ""
    _type_hash: ClassVar[str] = ""
    _data_schema: ClassVar[str] = ""
    # ROS 2 types only (from .msg/.srv/.action files, or .idl with miro-idl --ros2): the ROS 2
    # type name (`std_msgs/msg/Header`; DDS names it `std_msgs::msg::dds_::Header_`) and its
    # RIHS01 type hash, as rosidl_generator_type_description computes it.
    _ros2_type: ClassVar[str] = ""
    _ros2_type_hash: ClassVar[str] = ""

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if cls.__dict__.get("_type_hash"):
            registry.register(cls)

    def serialize(self) -> bytes:
        raise NotImplementedError  # pragma: no cover - generated classes implement it

    @classmethod
    def deserialize(cls, data: bytes | bytearray | memoryview) -> Self:
        raise NotImplementedError  # pragma: no cover - generated classes implement it

    def _encode(self, buf: Encoder) -> None:
        raise NotImplementedError  # pragma: no cover - generated classes implement it


# ---- unions ------------------------------------------------------------------------------------


class IdlUnion(IdlType):
    """Base of generated unions: discriminator `_d`, value `_v`, one property per branch.

    `U(branch=value)` selects a branch (the discriminator becomes the branch's first label, or
    for the default branch a value no label uses, chosen as Cyclone DDS does); `U(d, v)` sets
    both; `U()` is the first branch with its type's default value.
    """

    __slots__ = ("_d", "_v")

    _type_name: ClassVar[str] = ""
    _branches: ClassVar[dict[str, tuple[Any, ...]]] = {}  # branch -> labels (empty: default)
    _labels: ClassVar[dict[Any, str]] = {}  # label -> branch
    _default_branch: ClassVar[str | None] = None
    _default_discriminator: ClassVar[Any] = None
    _zero: ClassVar[dict[str, Callable[[], Any]]] = {}  # branch -> default value factory

    def __init__(self, *args: Any, **branch: Any) -> None:
        if args:
            if len(args) != 2 or branch:
                raise TypeError(
                    f"{type(self).__name__}() takes (discriminator, value) or one branch=value"
                )
            self._d, self._v = args
            return
        if len(branch) > 1:
            raise TypeError(f"{type(self).__name__}() takes a single branch=value")
        if branch:
            ((name, value),) = branch.items()
        else:
            name = next(iter(self._branches))
            value = self._zero[name]()
        self._set(name, value)

    def _set(self, name: str, value: Any) -> None:
        labels = self._branches.get(name)
        if labels is None:
            raise TypeError(f"{type(self).__name__} has no branch '{name}'")
        self._d = labels[0] if labels else self._default_discriminator
        self._v = value

    def _get(self, name: str) -> Any:
        active = self._branch()
        if active != name:
            raise AttributeError(
                f"{type(self).__name__}: branch '{name}' is not active "
                f"(discriminator {self._d!r} selects {active or 'no branch'})"
            )
        return self._v

    def _branch(self) -> str | None:
        """The branch the discriminator selects (None: no branch is active)."""
        return self._labels.get(self._d, self._default_branch)

    def __eq__(self, other: object) -> bool:
        return type(other) is type(self) and (self._d, self._v) == (other._d, other._v)

    __hash__ = None  # type: ignore[assignment]  # mutable

    def __repr__(self) -> str:
        return self._repr_with(repr)

    def _repr_with(self, show: Callable[[Any], str]) -> str:
        """`U(branch=value)` when the discriminator is the branch's usual one, else `U(d, v)`;
        the value as `show` gives it (the tools abridge long ones)."""
        name = self._branch()
        if name is not None:
            labels = self._branches[name]
            if self._d == (labels[0] if labels else self._default_discriminator):
                return f"{type(self).__name__}({name}={show(self._v)})"
        return f"{type(self).__name__}({self._d!r}, {show(self._v)})"


def default_discriminator(kind: str, labels: set[Any], enum_size: int = 0) -> Any:
    """The discriminator a union's default branch gets, chosen as Cyclone DDS chooses it."""
    if kind == "enum":
        return next(i for i in range(enum_size + 1) if i not in labels)
    if kind == "boolean":
        return True not in labels
    if kind == "char":
        return next(chr(i) for i in range(256) if chr(i) not in labels)
    if kind in ("octet", "uint8") or kind.startswith("unsigned"):
        return next(i for i in range(1 << 64) if i not in labels)
    i = -1
    while i in labels:
        i -= 1
    return i
