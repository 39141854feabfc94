"""Computational units in Python: the worker process ``kpl run`` starts for a spec's
``python.unit`` (docs/python.md, "Units in Python"; the protocol is in docs/process-units.md).

A unit is a function or a class in a module beside the spec (or installed). A function is called
once per input (or per synchronised state) with the latest value of each input, in the order the
spec names them, and the spec's own parameters as keyword arguments; what it returns is the
unit's output (``None``: no output this time)::

    # vehicle_kind.py
    def classify(tracks, *, truck_length=7.5):
        return [{"id": t["id"], "kind": "truck" if t["size"] > truck_length else "car"} for t in tracks]

    // the spec
    compute kinds : list<Kind> = python.unit(tracks, module: "vehicle_kind", function: "classify",
                                             truck_length: 8.0)

A class is made once per worker with the parameters (``Detector(threshold=0.5)``) and its
instance called as a function is; it keeps its state between calls (not across a restart of
the worker). ``close()``, if it has one, is called when the run ends.

The worker reads frames from its standard input and writes them to the standard output it was
started with; what the unit prints goes to standard error (kpl shows it), so it cannot break the
protocol. Run it as ``python -m kpl.unit``; kpl does.
"""

from __future__ import annotations

import importlib
import inspect
import json
import os
import struct
import sys
import traceback
from typing import Any, BinaryIO, Callable

from . import wire

#: The process-unit protocol this worker speaks (docs/process-units.md).
PROTOCOL = 1

_FRAME = struct.Struct("<IB")
_CALL = struct.Struct("<qqI")
_U32 = struct.Struct("<I")
_ABSENT = 0xFFFF_FFFF
#: The largest frame either side accepts (256 MiB), as kpl does.
MAX_FRAME = 256 << 20


class ProtocolError(Exception):
    """Bytes from kpl that are not a frame of this protocol."""


def _read_exactly(stream: BinaryIO, n: int) -> bytes | None:
    data = stream.read(n)
    if not data:
        return None
    while len(data) < n:
        more = stream.read(n - len(data))
        if not more:
            raise ProtocolError(f"the input ended inside a frame ({len(data)} of {n} bytes)")
        data += more
    return data


def read_frame(stream: BinaryIO) -> tuple[bytes, bytes] | None:
    """One frame: its kind (one byte) and its body; ``None`` at the end of the input."""
    head = _read_exactly(stream, 5)
    if head is None:
        return None
    length, kind = _FRAME.unpack(head)
    if length < 1 or length > MAX_FRAME:
        raise ProtocolError(f"a frame of {length} bytes (at most {MAX_FRAME})")
    body = _read_exactly(stream, length - 1) if length > 1 else b""
    if body is None:
        raise ProtocolError("the input ended inside a frame")
    return bytes([kind]), body


def write_frame(stream: BinaryIO, kind: bytes, body: bytes = b"") -> None:
    stream.write(_FRAME.pack(len(body) + 1, kind[0]))
    if body:
        stream.write(body)
    stream.flush()


def _error(message: str, exc: BaseException | None = None) -> bytes:
    trace = "".join(traceback.format_exception(exc)) if exc is not None else ""
    return json.dumps({"error": message, "traceback": trace}).encode()


def _numpy_floats() -> Callable[[bytes, int, int], Any]:
    import numpy

    little = numpy.dtype("<f8")

    def floats(b: bytes, at: int, n: int) -> Any:
        # A read-only view of the frame's bytes: no copy of the numbers.
        return numpy.frombuffer(b, dtype=little, count=n, offset=at)

    return floats


def _plain(value: Any) -> Any:
    """NumPy scalars and non-float arrays as the Python values the wire format knows; float64
    arrays stay as they are (sent packed, without a copy per number)."""
    kind = type(value)
    if kind in (float, int, str, bool) or value is None:
        return value
    if kind is dict:
        return {k: _plain(v) for k, v in value.items()}
    if kind in (list, tuple) and not isinstance(value, (wire.Vec2, wire.Box)):
        return [_plain(v) for v in value]
    numpy = sys.modules.get("numpy")
    if numpy is not None:
        if isinstance(value, numpy.ndarray):
            if value.dtype == numpy.float64 and value.ndim == 1:
                # Native byte order: its buffer's format is `d`, which the wire packs in one copy.
                return numpy.ascontiguousarray(value, dtype=numpy.float64)
            return _plain(value.tolist())
        if isinstance(value, numpy.generic):
            return value.item()
    return value


class Unit:
    """The loaded unit: what the handshake named, ready to be called."""

    def __init__(self, hello: dict) -> None:
        for folder in reversed(hello.get("path", [])):
            if folder not in sys.path:
                sys.path.insert(0, folder)
        arrays = hello.get("arrays", "numpy")
        self.floats = _numpy_floats() if arrays == "numpy" else None
        module = importlib.import_module(hello["module"])
        name = hello["function"]
        try:
            target = getattr(module, name)
        except AttributeError:
            names = sorted(n for n in vars(module) if not n.startswith("_"))
            raise LookupError(
                f"module `{hello['module']}` ({getattr(module, '__file__', '?')}) has no `{name}`"
                f"; it has: {', '.join(names) or 'nothing public'}"
            ) from None
        params = hello.get("params", {})
        inputs = hello.get("inputs", [])
        self.close: Callable[[], Any] | None = None
        if inspect.isclass(target):
            self.kind = "class"
            instance = target(**params)
            if not callable(instance):
                raise TypeError(f"class `{name}` has no __call__: its instances cannot be called with the inputs")
            self.call = instance
            self.close = getattr(instance, "close", None)
            inspect.signature(instance).bind(*([None] * len(inputs)))
        elif callable(target):
            self.kind = "function"
            signature = inspect.signature(target)
            signature.bind(*([None] * len(inputs)), **params)
            if params:
                self.call = lambda *args: target(*args, **params)
            else:
                self.call = target
        else:
            raise TypeError(f"`{name}` in `{hello['module']}` is a {type(target).__name__}, not a function or a class")

    def on_call(self, body: bytes) -> tuple[bytes, bytes]:
        valid, now, n = _CALL.unpack_from(body)
        at = _CALL.size
        args = []
        for _ in range(n):
            (length,) = _U32.unpack_from(body, at)
            at += 4
            if length == _ABSENT:
                args.append(None)
                continue
            args.append(wire.decode(body[at : at + length], self.floats).value)
            at += length
        try:
            result = self.call(*args)
        except Exception as e:  # the unit's own error: reported with its traceback, the worker lives on
            return b"E", _error(f"{type(e).__name__}: {e}", e)
        if result is None:
            return b"O", b""
        try:
            return b"O", wire.encode_sample(valid, now, _plain(result))
        except Exception as e:  # a value the wire format has no encoding for: the unit's failure, not the worker's
            return b"E", _error(f"the unit returned a value KPL cannot take: {e}")


def serve(reader: BinaryIO, writer: BinaryIO) -> int:
    """Speaks the protocol until kpl says quit or closes the input; the exit status."""
    first = read_frame(reader)
    if first is None:
        return 0
    kind, body = first
    if kind != b"H":
        write_frame(writer, b"E", _error(f"expected the hello frame, got {kind!r}"))
        return 2
    hello = json.loads(body)
    if hello.get("protocol") != PROTOCOL:
        write_frame(writer, b"E", _error(f"kpl speaks protocol {hello.get('protocol')}; this worker speaks {PROTOCOL}"))
        return 2
    try:
        unit = Unit(hello)
    except Exception as e:
        write_frame(writer, b"E", _error(f"{type(e).__name__}: {e}", e))
        return 1
    ready = {
        "protocol": PROTOCOL,
        "wire": wire.VERSION,
        "kind": unit.kind,
        "implementation": f"python {sys.version.split()[0]}",
        "pid": os.getpid(),
    }
    write_frame(writer, b"R", json.dumps(ready).encode())
    while True:
        frame = read_frame(reader)
        if frame is None or frame[0] == b"Q":
            break
        kind, body = frame
        if kind != b"C":
            write_frame(writer, b"E", _error(f"unexpected frame {kind!r}"))
            continue
        out_kind, out = unit.on_call(body)
        write_frame(writer, out_kind, out)
    if unit.close is not None:
        unit.close()
    return 0


def main() -> int:
    # The protocol keeps the standard output the worker was started with; the unit's prints go
    # to standard error.
    protocol_out = os.fdopen(os.dup(1), "wb", buffering=1 << 16)
    os.dup2(2, 1)
    sys.stdout = sys.stderr
    protocol_in = os.fdopen(os.dup(0), "rb", buffering=1 << 16)
    try:
        return serve(protocol_in, protocol_out)
    except ProtocolError as e:
        print(f"kpl.unit: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
