"""Values described by TypeCodes: `any`, and moving generated types' CDR in and out of GIOP.

Generated types encode themselves as XCDR1 laid out from a multiple of 8, with object references
as (repository id, endpoint, key). Inside a GIOP message a value may start anywhere (after the
TypeCode of an `any`, after the repository id of an exception) and references are IORs. The
`transcode` function copies a value from one layout to the other, guided by its TypeCode; the
TypeCode of a generated type is built once from the data schema it carries (its IDL text). When
no generated type fits an `any` received, the value is decoded generically (`to_python`):
structs as dicts, unions as (discriminator, value), enums as enumerator names.
"""

from __future__ import annotations

import importlib
import threading
from array import array
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from miro_gen.corba import typecode as tcm
from miro_gen.corba.ior import IOR, GiopBody, ior_from_ref, ref_from_ior
from miro_gen.corba.schema import SchemaReader
from miro_gen.corba.typecode import PRIMITIVES, K, TypeCode
from miro_gen.exceptions import BAD_PARAM, MARSHAL, UserException
from miro_gen.runtime import cdr, registry
from miro_gen.runtime.cdr import LE, ObjectRef
from miro_gen.runtime.cdrstream import CdrInput, CdrOutput

MIRO_REFS = "miro"  # object references as (repository id, endpoint, key): generated CDR
GIOP_REFS = "giop"  # object references as IORs
_MAX_DEPTH = 200


@dataclass
class Any_:
    """A CORBA `any`: a TypeCode and a value (a generated type's instance, or what
    `to_python` makes of types without one)."""

    typecode: TypeCode
    value: Any


# ---- TypeCodes of generated types -------------------------------------------------------------

_cache: dict[type, TypeCode] = {}
_lock = threading.Lock()


def typecode_for(cls: type) -> TypeCode:
    """The TypeCode of a generated struct, union or exception class (from its data schema)."""
    tc = _cache.get(cls)
    if tc is None:
        with _lock:
            tc = _cache.get(cls) or _build(cls)
            _cache[cls] = tc
    return tc


def _build(cls: type) -> TypeCode:
    schema = getattr(cls, "_data_schema", "")
    name = getattr(cls, "_type_name", "")
    if not schema or not name:
        raise BAD_PARAM(f"{cls.__name__} is not a generated IDL type (it has no data schema)")
    # Schemas drop #pragma prefix: the generated classes know the real repository ids.
    repo_ids = {c._type_name: c._repo_id for c in registry.known_types()}
    tc = SchemaReader(schema, repo_ids).types.get(name)
    if tc is None:  # pragma: no cover - a schema always declares its type
        raise BAD_PARAM(f"the data schema of {name} does not declare it")
    if issubclass(cls, UserException):
        tc.kind = K.tk_except
    tc.id = getattr(cls, "_repo_id", "") or tc.id
    return tc


def class_for(tc: TypeCode) -> type | None:
    """The generated class for a named struct, union or exception TypeCode, if there is one."""
    tc = tc.resolved()
    if tc.kind not in (K.tk_struct, K.tk_union, K.tk_except) or not tc.id:
        return None
    cls = registry.find_repo_id(tc.id)
    if cls is None:
        cls = _by_module_path(tc.id)
    if cls is not None and typecode_for(cls).equivalent(tc):
        return cls
    return None


def _by_module_path(repo_id: str) -> type | None:
    """`IDL:Mod/Sub/Name:1.0` -> `Mod.Sub.Name`, imported (generated packages load lazily)."""
    if not repo_id.startswith("IDL:"):
        return None
    parts = repo_id[4:].rpartition(":")[0].split("/")
    for start in range(len(parts) - 1):
        names = parts[start:]
        if not all(n.isidentifier() for n in names):
            continue
        try:
            obj: Any = importlib.import_module(names[0])
            for n in names[1:]:
                obj = getattr(obj, n)
        except (ImportError, AttributeError):
            continue
        return obj if isinstance(obj, type) else None
    return None


# ---- copying values between layouts ------------------------------------------------------------

_READ: dict[int, Callable[[CdrInput], Any]] = {
    K.tk_short: CdrInput.short, K.tk_long: CdrInput.long, K.tk_ushort: CdrInput.ushort,
    K.tk_ulong: CdrInput.ulong, K.tk_float: CdrInput.float, K.tk_double: CdrInput.double,
    K.tk_boolean: CdrInput.boolean, K.tk_char: CdrInput.char, K.tk_octet: CdrInput.octet,
    K.tk_longlong: CdrInput.longlong, K.tk_ulonglong: CdrInput.ulonglong,
}  # fmt: skip
_WRITE: dict[int, Callable[[CdrOutput, Any], None]] = {
    K.tk_short: CdrOutput.short, K.tk_long: CdrOutput.long, K.tk_ushort: CdrOutput.ushort,
    K.tk_ulong: CdrOutput.ulong, K.tk_float: CdrOutput.float, K.tk_double: CdrOutput.double,
    K.tk_boolean: CdrOutput.boolean, K.tk_char: CdrOutput.char, K.tk_octet: CdrOutput.octet,
    K.tk_longlong: CdrOutput.longlong, K.tk_ulonglong: CdrOutput.ulonglong,
}  # fmt: skip


def transcode(
    tc: TypeCode, src: CdrInput, dst: CdrOutput, refs_in: str, refs_out: str, depth: int = 0
) -> None:
    """Copy one value of type `tc` from `src` to `dst` (little-endian), realigning it and
    converting object references between the two layouts."""
    if depth > _MAX_DEPTH:
        raise MARSHAL("value nested too deeply")
    tc = tc.resolved()
    k = tc.kind
    if k in _WRITE:
        _WRITE[k](dst, _READ[k](src))
    elif k in (K.tk_string,):
        dst.string(src.string())
    elif k in (K.tk_struct, K.tk_except):
        for _, m in tc.members:
            transcode(m, src, dst, refs_in, refs_out, depth + 1)
    elif k == K.tk_enum:
        dst.ulong(src.ulong())
    elif k == K.tk_sequence:
        assert tc.content is not None
        n = src.length(_min_size(tc.content))
        dst.length(n)
        _elements(tc.content, n, src, dst, refs_in, refs_out, depth)
    elif k == K.tk_array:
        assert tc.content is not None
        _elements(tc.content, tc.length, src, dst, refs_in, refs_out, depth)
    elif k == K.tk_union:
        assert tc.discriminator is not None
        label = tcm.read_label(src, tc.discriminator)
        tcm.write_label(dst, tc.discriminator, label)
        branch = _branch(tc, label)
        if branch is not None:
            transcode(branch, src, dst, refs_in, refs_out, depth + 1)
    elif k in (K.tk_objref, K.tk_abstract_interface):
        _write_ref(dst, _read_ref(src, refs_in), refs_out)
    elif k == K.tk_any:
        inner = tcm.read_typecode(src)
        tcm.write_typecode(dst, inner)
        transcode(inner, src, dst, refs_in, refs_out, depth + 1)
    elif k == K.tk_TypeCode:
        tcm.write_typecode(dst, tcm.read_typecode(src))
    elif k in (K.tk_null, K.tk_void):
        pass
    elif k in (K.tk_wchar, K.tk_wstring):
        _wide(k, src, dst)
    else:
        raise MARSHAL(f"values of TypeCode kind {k.name} are not supported")


def _elements(
    tc: TypeCode, n: int, src: CdrInput, dst: CdrOutput, refs_in: str, refs_out: str, depth: int
) -> None:
    r = tc.resolved()
    prim = PRIMITIVES.get(r.kind)
    if prim is not None and n:
        size, code = prim
        src.align(size)
        raw = src.raw(n * size)
        if src.e != LE and size > 1:
            values = array(code)
            values.frombytes(raw)
            values.byteswap()
            raw = values.tobytes()
        dst.align(size)
        dst.raw(raw)
        return
    for _ in range(n):
        transcode(r, src, dst, refs_in, refs_out, depth + 1)


def _branch(tc: TypeCode, label: Any) -> TypeCode | None:
    for i, (value, _, member) in enumerate(tc.cases):
        if i != tc.default_index and value == label:
            return member
    return tc.cases[tc.default_index][2] if tc.default_index >= 0 else None


def _wide(k: K, src: CdrInput, dst: CdrOutput) -> None:
    """wchar/wstring as GIOP 1.2 writes them (octet counts, UTF-16): copied as they are."""
    if k == K.tk_wchar:
        n = src.octet()
        dst.octet(n)
        dst.raw(src.raw(n))
    else:
        n = src.length(1)
        dst.length(n)
        dst.raw(src.raw(n))


def _min_size(tc: TypeCode) -> int:
    r = tc.resolved()
    prim = PRIMITIVES.get(r.kind)
    if prim is not None:
        return prim[0]
    return 4 if r.kind in (K.tk_string, K.tk_sequence, K.tk_enum, K.tk_objref) else 0


def _read_ref(src: CdrInput, refs: str) -> ObjectRef:
    if refs == GIOP_REFS:
        return ref_from_ior(IOR.read(src))
    return ObjectRef(src.string(), src.string(), src.octets())


def _write_ref(dst: CdrOutput, ref: ObjectRef, refs: str) -> None:
    if refs == GIOP_REFS:
        ior_from_ref(ref).write(dst)
    else:
        dst.string(ref.repo_id)
        dst.string(ref.endpoint)
        dst.octets(ref.key)


def has_refs(tc: TypeCode, seen: set[int] | None = None) -> bool:
    """Whether values of `tc` may hold object references (or anys, which may)."""
    seen = set() if seen is None else seen
    tc = tc.resolved()
    if id(tc) in seen:
        return False
    seen.add(id(tc))
    if tc.kind in (K.tk_objref, K.tk_any, K.tk_abstract_interface):
        return True
    inner = [m for _, m in tc.members] + [c for *_, c in tc.cases]
    inner += [t for t in (tc.content, tc.discriminator) if t is not None]
    return any(has_refs(t, seen) for t in inner)


# ---- generated values in and out of GIOP streams -------------------------------------------------


def write_value(out: CdrOutput, tc: TypeCode, value: Any) -> None:
    """A generated type's value (or a plain Python one, see `from_python`) at the end of `out`."""
    serialize = getattr(value, "serialize", None)
    if serialize is None:
        from_python(out, tc, value)
        return
    data = serialize()
    if len(out.buf) % 8 == 0 and not has_refs(tc):
        out.raw(memoryview(data)[4:])  # the same layout: copied as it is
        return
    # Generated encodings align from the end of their 4-byte header.
    src = CdrInput(data[4:], 0, cdr.header_endianness(data))
    transcode(tc, src, out, MIRO_REFS, GIOP_REFS)


def read_value(inp: CdrInput, tc: TypeCode) -> Any:
    """A value of type `tc` from a GIOP stream: an instance of the generated class when one is
    imported or importable, else what `to_python` makes of it."""
    cls = class_for(tc)
    if cls is None:
        return to_python(inp, tc)
    out = CdrOutput()
    transcode(tc, inp, out, GIOP_REFS, GIOP_REFS)
    return cls.deserialize(giop_body(out.buf))  # type: ignore[attr-defined]


def giop_body(payload: bytes | bytearray | memoryview, little: bool = True) -> cdr.ForeignBody:
    """`payload` (CDR laid out from a multiple of 8, references as IORs) as the body that
    generated decoders read: the encapsulation header first."""
    return GiopBody((b"\x00\x01\x00\x00" if little else b"\x00\x00\x00\x00") + bytes(payload))


# ---- generic values ----------------------------------------------------------------------------


def to_python(inp: CdrInput, tc: TypeCode, depth: int = 0) -> Any:
    """A value with no generated class, as plain Python data."""
    if depth > _MAX_DEPTH:
        raise MARSHAL("value nested too deeply")
    tc = tc.resolved()
    k = tc.kind
    if k in _READ:
        return _READ[k](inp)
    if k == K.tk_string:
        return inp.string()
    if k in (K.tk_struct, K.tk_except):
        return {name: to_python(inp, m, depth + 1) for name, m in tc.members}
    if k == K.tk_enum:
        i = inp.ulong()
        if i >= len(tc.enumerators):
            raise MARSHAL(f"{tc.name}: {i} is not an enumerator")
        return tc.enumerators[i]
    if k in (K.tk_sequence, K.tk_array):
        assert tc.content is not None
        n = inp.length(_min_size(tc.content)) if k == K.tk_sequence else tc.length
        if tc.content.resolved().kind == K.tk_octet:
            return inp.raw(n)
        return [to_python(inp, tc.content, depth + 1) for _ in range(n)]
    if k == K.tk_union:
        assert tc.discriminator is not None
        label = tcm.read_label(inp, tc.discriminator)
        branch = _branch(tc, label)
        return label, (to_python(inp, branch, depth + 1) if branch is not None else None)
    if k in (K.tk_objref, K.tk_abstract_interface):
        return _read_ref(inp, GIOP_REFS)
    if k == K.tk_any:
        inner = tcm.read_typecode(inp)
        return Any_(inner, read_value(inp, inner))
    if k == K.tk_TypeCode:
        return tcm.read_typecode(inp)
    if k in (K.tk_null, K.tk_void):
        return None
    if k == K.tk_wstring:
        return inp.raw(inp.length(1)).decode("utf-16", "replace")
    if k == K.tk_wchar:
        return inp.raw(inp.octet()).decode("utf-16", "replace")
    raise MARSHAL(f"values of TypeCode kind {k.name} are not supported")


def from_python(out: CdrOutput, tc: TypeCode, value: Any, depth: int = 0) -> None:
    """Plain Python data (as `to_python` returns it, or a generated value) as type `tc`."""
    if depth > _MAX_DEPTH:
        raise BAD_PARAM("value nested too deeply")
    tc = tc.resolved()
    k = tc.kind
    try:
        if hasattr(value, "serialize") and k in (K.tk_struct, K.tk_union, K.tk_except):
            write_value(out, tc, value)
        elif k in _WRITE:
            _WRITE[k](out, value)
        elif k == K.tk_string:
            out.string(value)
        elif k in (K.tk_struct, K.tk_except):
            for name, m in tc.members:
                from_python(out, m, value[name], depth + 1)
        elif k == K.tk_enum:
            out.ulong(tc.enumerators.index(value) if isinstance(value, str) else int(value))
        elif k in (K.tk_sequence, K.tk_array):
            assert tc.content is not None
            if k == K.tk_sequence:
                out.length(len(value))
            elif len(value) != tc.length:
                raise BAD_PARAM(f"array of {tc.length} elements given {len(value)}")
            if tc.content.resolved().kind == K.tk_octet and isinstance(value, bytes | bytearray):
                out.raw(value)
            else:
                for v in value:
                    from_python(out, tc.content, v, depth + 1)
        elif k == K.tk_union:
            assert tc.discriminator is not None
            label, inner = value
            tcm.write_label(out, tc.discriminator, label)
            branch = _branch(tc, label)
            if branch is not None:
                from_python(out, branch, inner, depth + 1)
        elif k == K.tk_objref:
            _write_ref(out, _as_ref(value), GIOP_REFS)
        elif k == K.tk_any:
            write_any(out, value)
        elif k == K.tk_TypeCode:
            tcm.write_typecode(out, value)
        elif k not in (K.tk_null, K.tk_void):
            raise BAD_PARAM(f"values of TypeCode kind {k.name} are not supported")
    except (TypeError, ValueError, KeyError, IndexError, AttributeError, OverflowError) as e:
        raise BAD_PARAM(f"{tc.name or k.name}: {e}") from None


def _as_ref(value: Any) -> ObjectRef:
    if value is None:
        return ObjectRef()
    if isinstance(value, ObjectRef):
        return value
    ref = getattr(value, "_ref", None)
    if isinstance(ref, ObjectRef):
        return ref
    raise BAD_PARAM(f"expected an object reference, got {type(value).__name__}")


def typecode_of(value: Any) -> TypeCode:
    """The TypeCode an `any` holding `value` carries: a generated type's, or that of a plain
    Python value (bool, int as long or long long, float as double, str, bytes)."""
    if isinstance(value, Any_):
        return value.typecode
    if hasattr(value, "_data_schema"):
        return typecode_for(type(value))
    if value is None:
        return tcm.simple(K.tk_null)
    if isinstance(value, bool):
        return tcm.simple(K.tk_boolean)
    if isinstance(value, int):
        return tcm.simple(K.tk_long if -(1 << 31) <= value < 1 << 31 else K.tk_longlong)
    if isinstance(value, float):
        return tcm.simple(K.tk_double)
    if isinstance(value, str):
        return tcm.string_tc()
    if isinstance(value, bytes | bytearray):
        return TypeCode(K.tk_sequence, content=tcm.simple(K.tk_octet))
    raise BAD_PARAM(f"cannot put a {type(value).__name__} in an any: give a generated type")


def write_any(out: CdrOutput, value: Any) -> None:
    tc = typecode_of(value)
    tcm.write_typecode(out, tc)
    write_value(out, tc, value.value if isinstance(value, Any_) else value)


def read_any(inp: CdrInput) -> Any:
    """An `any`'s value: a generated type's instance, plain Python data, or `Any_` when the
    TypeCode says more than the value does (an alias, say)."""
    tc = tcm.read_typecode(inp)
    return read_value(inp, tc)
