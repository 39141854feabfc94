"""KPL's wire format (docs/streams.md, "Messages"): the bytes of one zenoh payload.

A message is a sample (valid time, available time, value) or the end of a stream (how many samples
the producer published). Values describe themselves with a tag byte; this module maps them to
Python both ways:

=========  ==================  ==================================================
tag        KPL type            Python
=========  ==================  ==================================================
``t f``    ``bool``            ``bool``
``i``      ``int``             ``int``
``d``      ``duration``        :class:`Duration` (an ``int`` of microseconds)
``r``      ``float``           ``float``
``s``      ``string``          ``str``
``v``      ``vec2``            :class:`Vec2` (a named tuple ``x, y``)
``b``      ``box``             :class:`Box` (a named tuple ``x1, y1, x2, y2``)
``l``      ``list<T>``         ``list``
``F``      ``list<float>``     ``list`` of ``float`` (packed: no tag per number)
``o``      an object type      ``dict`` (the symbol is the attribute ``id``)
=========  ==================  ==================================================

Encoding goes the other way; besides, a ``tuple`` is a list, a ``datetime.timedelta`` a
duration, and a non-empty list of ``float`` (or an ``array.array('d')``, or anything that gives a
buffer of doubles, such as a NumPy ``float64`` array) is sent packed, as KPL sends it. KPL checks
what arrives against the stream's declared type: an ``int`` is accepted where a ``float`` or a
``duration`` is declared, a list of two (four) numbers where a ``vec2`` (``box``) is.
"""

from __future__ import annotations

import array
import datetime
import math
import struct
import sys
from dataclasses import dataclass
from typing import Any, NamedTuple, Union

#: The format version this module writes. It reads versions 1 and 2 (2 added packed float lists).
VERSION = 2
READS = (1, 2)

#: How deep lists and objects may nest in a value (as KPL's decoder allows).
MAX_DEPTH = 128

_HEADER = struct.Struct("<3sBc")
_TIMES = struct.Struct("<qq")
_U32 = struct.Struct("<I")
_I64 = struct.Struct("<q")
_U64 = struct.Struct("<Q")
_F64 = struct.Struct("<d")
_LITTLE = sys.byteorder == "little"


class Vec2(NamedTuple):
    """A KPL ``vec2``."""

    x: float
    y: float


class Box(NamedTuple):
    """A KPL ``box``: corners ``(x1, y1)`` and ``(x2, y2)``."""

    x1: float
    y1: float
    x2: float
    y2: float


class Duration(int):
    """A KPL ``duration``: whole microseconds."""

    def __repr__(self) -> str:
        return f"Duration({int(self)})"

    @classmethod
    def of(cls, delta: datetime.timedelta) -> "Duration":
        return cls(delta // datetime.timedelta(microseconds=1))


Value = Union[bool, int, float, str, Vec2, Box, Duration, list, dict]


@dataclass(frozen=True)
class Sample:
    """A sample of a stream: its valid and available times (integer microseconds; with
    ``--clock wall``, since the UNIX epoch) and its value."""

    valid: int
    available: int
    value: Any


@dataclass(frozen=True)
class End:
    """The end of a stream: the number of samples its producer published on it."""

    published: int


Message = Union[Sample, End]


class WireError(ValueError):
    """Bytes that are not a KPL message, or a Python value that has no KPL value."""


# --- encoding ---------------------------------------------------------------------------------


def encode_sample(valid: int, available: int, value: Any) -> bytes:
    """The message of a sample."""
    out = bytearray(_HEADER.pack(b"KPL", VERSION, b"S"))
    out += _TIMES.pack(_time(valid, "valid"), _time(available, "available"))
    _encode_value(value, out, 0)
    return bytes(out)


def encode_end(published: int) -> bytes:
    """The message that ends a stream after ``published`` samples."""
    return _HEADER.pack(b"KPL", VERSION, b"E") + _U64.pack(published)


def encode_value(value: Any) -> bytes:
    """The bytes of one value (tag and body), as inside a sample."""
    out = bytearray()
    _encode_value(value, out, 0)
    return bytes(out)


def _time(t: Any, name: str) -> int:
    if isinstance(t, bool) or not isinstance(t, int):
        raise WireError(f"the {name} time must be whole microseconds (an int), not {t!r}")
    if not -(2**63) <= t < 2**63:
        raise WireError(f"the {name} time {t} does not fit in 64 bits")
    return t


def _text(text: str, out: bytearray) -> None:
    data = text.encode("utf-8")
    out += _U32.pack(len(data))
    out += data


def _float(x: float, what: str) -> float:
    if not math.isfinite(x):
        raise WireError(f"{what}: KPL numbers are finite, not {x!r}")
    return x


def _encode_value(v: Any, out: bytearray, depth: int) -> None:
    if depth > MAX_DEPTH:
        raise WireError(f"the value nests deeper than {MAX_DEPTH}")
    if isinstance(v, bool):
        out += b"t" if v else b"f"
    elif isinstance(v, Duration):
        out += b"d" + _I64.pack(v)
    elif isinstance(v, datetime.timedelta):
        out += b"d" + _I64.pack(Duration.of(v))
    elif isinstance(v, int):
        if not -(2**63) <= v < 2**63:
            raise WireError(f"the int {v} does not fit in 64 bits")
        out += b"i" + _I64.pack(v)
    elif isinstance(v, float):
        out += b"r" + _F64.pack(_float(v, "a float"))
    elif isinstance(v, str):
        out += b"s"
        _text(v, out)
    elif isinstance(v, Vec2):
        out += b"v" + struct.pack("<2d", *(_float(float(x), "a vec2") for x in v))
    elif isinstance(v, Box):
        out += b"b" + struct.pack("<4d", *(_float(float(x), "a box") for x in v))
    elif isinstance(v, dict):
        out += b"o" + _U32.pack(len(v))
        # The symbol first, as KPL writes it.
        items = sorted(v.items(), key=lambda kv: kv[0] != "id")
        for name, item in items:
            if not isinstance(name, str):
                raise WireError(f"an object's attribute names are strings, not {name!r}")
            _text(name, out)
            _encode_value(item, out, depth + 1)
    elif isinstance(v, (list, tuple)):
        if v and all(type(x) is float for x in v):
            _encode_floats(v, out)
        else:
            out += b"l" + _U32.pack(len(v))
            for item in v:
                _encode_value(item, out, depth + 1)
    else:
        floats = _double_buffer(v)
        if floats is None:
            raise WireError(f"no KPL value for {v!r} (a {type(v).__name__})")
        _encode_floats(floats, out)


def _double_buffer(v: Any) -> "memoryview | None":
    """The doubles of an ``array.array('d')`` or any other buffer of C doubles, else None."""
    try:
        view = memoryview(v)
    except TypeError:
        return None
    if view.format not in ("d", "<d", "=d") or view.ndim != 1:
        return None
    return view


def _encode_floats(values: Any, out: bytearray) -> None:
    view = _double_buffer(values)
    if view is not None:
        # A buffer of doubles (NumPy's float64 arrays: format `<d` or `=d`, which array.array does
        # not take): its bytes in one copy.
        numbers = array.array("d")
        numbers.frombytes(view.tobytes())
    else:
        numbers = array.array("d", values)
    if not all(map(math.isfinite, numbers)):
        for x in numbers:
            _float(x, "a list of floats")
    if not _LITTLE:
        numbers.byteswap()
    out += b"F" + _U32.pack(len(numbers))
    out += numbers.tobytes()


# --- decoding ---------------------------------------------------------------------------------


def decode(payload: Any, floats: Any = None) -> Message:
    """One message: a :class:`Sample` or an :class:`End`. Raises :class:`WireError` on bytes that
    are not a KPL message of a version this module reads.

    ``floats``, if given, makes the value of each packed list of floats (``list<float>`` as KPL
    sends it) from the message's bytes: it is called with the bytes, the offset of the first
    number and their count, and may keep a view of them instead of copying each number
    (``numpy.frombuffer``; :mod:`kpl.unit` does). Without it such a list is a ``list``."""
    b = payload if isinstance(payload, bytes) else bytes(payload)
    if len(b) < 5:
        raise WireError(f"{len(b)} bytes: too short for a KPL message")
    magic, version, kind = _HEADER.unpack_from(b)
    if magic != b"KPL":
        raise WireError("not a KPL message (it does not start with `KPL`)")
    if version not in READS:
        raise WireError(f"KPL message format {version}; this package reads {READS}")
    if kind == b"E":
        if len(b) != 13:
            raise WireError(f"an end message is 13 bytes, not {len(b)}")
        return End(_U64.unpack_from(b, 5)[0])
    if kind != b"S":
        raise WireError(f"unknown message kind {kind!r}")
    if len(b) < 22:
        raise WireError(f"{len(b)} bytes: too short for a sample")
    valid, available = _TIMES.unpack_from(b, 5)
    value, end = _decode_value(b, 21, 0, floats)
    if end != len(b):
        raise WireError(f"{len(b) - end} bytes after the value")
    return Sample(valid, available, value)


def decode_value(data: Any) -> Any:
    """One value (tag and body), as :func:`encode_value` writes it."""
    b = bytes(data)
    value, end = _decode_value(b, 0, 0)
    if end != len(b):
        raise WireError(f"{len(b) - end} bytes after the value")
    return value


def _need(b: bytes, at: int, n: int) -> None:
    if at + n > len(b):
        raise WireError(f"the value is cut short at byte {len(b)} (needs {at + n})")


def _finite(x: float, at: int) -> float:
    if not math.isfinite(x):
        raise WireError(f"a number that is not finite ({x}) at byte {at}")
    return x


def _decode_text(b: bytes, at: int) -> "tuple[str, int]":
    _need(b, at, 4)
    (n,) = _U32.unpack_from(b, at)
    _need(b, at + 4, n)
    try:
        return b[at + 4 : at + 4 + n].decode("utf-8"), at + 4 + n
    except UnicodeDecodeError as e:
        raise WireError(f"a string that is not UTF-8 at byte {at}: {e}") from None


def _decode_value(b: bytes, at: int, depth: int, floats: Any = None) -> "tuple[Any, int]":
    if depth > MAX_DEPTH:
        raise WireError(f"the value nests deeper than {MAX_DEPTH}")
    _need(b, at, 1)
    tag, at = b[at : at + 1], at + 1
    if tag in (b"t", b"f"):
        return tag == b"t", at
    if tag in (b"i", b"d"):
        _need(b, at, 8)
        (n,) = _I64.unpack_from(b, at)
        return (Duration(n) if tag == b"d" else n), at + 8
    if tag == b"r":
        _need(b, at, 8)
        return _finite(_F64.unpack_from(b, at)[0], at), at + 8
    if tag == b"v":
        _need(b, at, 16)
        return Vec2(*(_finite(x, at) for x in struct.unpack_from("<2d", b, at))), at + 16
    if tag == b"b":
        _need(b, at, 32)
        return Box(*(_finite(x, at) for x in struct.unpack_from("<4d", b, at))), at + 32
    if tag == b"s":
        return _decode_text(b, at)
    if tag == b"F":
        _need(b, at, 4)
        (n,) = _U32.unpack_from(b, at)
        _need(b, at + 4, 8 * n)
        if floats is not None:
            return floats(b, at + 4, n), at + 4 + 8 * n
        numbers = array.array("d")
        numbers.frombytes(b[at + 4 : at + 4 + 8 * n])
        if not _LITTLE:
            numbers.byteswap()
        values = numbers.tolist()
        if not all(map(math.isfinite, values)):
            raise WireError(f"a packed list with a number that is not finite at byte {at}")
        return values, at + 4 + 8 * n
    if tag in (b"l", b"o"):
        _need(b, at, 4)
        (count,) = _U32.unpack_from(b, at)
        at += 4
        # Every item takes at least one byte: a count beyond what is left is a lie.
        _need(b, at, count)
        if tag == b"l":
            items = []
            for _ in range(count):
                item, at = _decode_value(b, at, depth + 1, floats)
                items.append(item)
            return items, at
        record = {}
        for _ in range(count):
            name, at = _decode_text(b, at)
            record[name], at = _decode_value(b, at, depth + 1, floats)
        return record, at
    raise WireError(f"unknown value tag {tag!r} at byte {at - 1}")
