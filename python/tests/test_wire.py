"""The wire codec, the keys and the envelopes of the `kpl` package (tests/python.rs runs these with
`python -m unittest` in python/, so they test the repository's sources).

The reference is docs/streams.md: its Python blocks (the decoder of "Messages") decode what this
package encodes, and its examples of keys are checked here.
"""

import array
import datetime
import math
import random
import re
import struct
import unittest
from pathlib import Path

from kpl import envelope, keys, wire
from kpl.session import _Sequence
from kpl.wire import Box, Duration, End, Sample, Vec2, WireError

DOCS = Path(__file__).resolve().parents[2] / "docs" / "streams.md"


def documented_decoder():
    """The `decode` of the Python block of docs/streams.md's section "On the wire"."""
    section = DOCS.read_text(encoding="utf-8").split("## On the wire", 1)[1]
    block = next(b for b in re.findall(r"```python\n(.*?)```", section, re.S) if "def decode" in b)
    namespace = {}
    exec(block, namespace)
    return namespace["decode"]


def plain(v):
    """A value as the documented decoder gives it: named tuples as lists, durations as ints."""
    if isinstance(v, (Vec2, Box)):
        return [float(x) for x in v]
    if isinstance(v, bool):
        return v
    if isinstance(v, Duration):
        return int(v)
    if isinstance(v, datetime.timedelta):
        return int(Duration.of(v))
    if isinstance(v, (list, tuple, array.array)):
        return [plain(x) for x in v]
    if isinstance(v, dict):
        return {k: plain(x) for k, x in v.items()}
    return v


def random_value(rng, depth=0):
    kinds = ["bool", "int", "float", "str", "vec2", "box", "duration"]
    if depth < 3:
        kinds += ["list", "floats", "object"]
    kind = rng.choice(kinds)
    if kind == "bool":
        return rng.random() < 0.5
    if kind == "int":
        return rng.randint(-(2**63), 2**63 - 1)
    if kind == "float":
        return rng.choice([0.0, -0.0, 1e-308, 5e-324, 1.7e308, rng.uniform(-1e9, 1e9)])
    if kind == "str":
        return "".join(rng.choice("aé\"\\\n🌡/%") for _ in range(rng.randint(0, 8)))
    if kind == "vec2":
        return Vec2(rng.uniform(-1e6, 1e6), rng.uniform(-1e6, 1e6))
    if kind == "box":
        return Box(*(rng.uniform(-10, 10) for _ in range(4)))
    if kind == "duration":
        return Duration(rng.randint(-(10**12), 10**12))
    if kind == "floats":
        return [rng.uniform(-1, 1) for _ in range(rng.randint(1, 40))]
    if kind == "list":
        return [random_value(rng, depth + 1) for _ in range(rng.randint(0, 4))]
    record = {"id": f"o{rng.randint(0, 99)}"}
    for i in range(rng.randint(0, 4)):
        record[f"a{i}"] = random_value(rng, depth + 1)
    return record


class Codec(unittest.TestCase):
    def test_every_type_round_trips_with_its_python_type(self):
        value = {
            "id": "rd1",
            "ok": True,
            "no": False,
            "n": -(2**63),
            "m": 2**63 - 1,
            "temp": 21.5,
            "label": "wärme \"1\" 🌡",
            "pos": Vec2(1.5, -2.0),
            "box": Box(0.0, 1.0, 2.0, 3.0),
            "age": Duration(1_500_000),
            "spectrum": [0.1, 0.2, 1e300],
            "mixed": [1, 2.5, "x", [], {}],
            "empty": [],
        }
        message = wire.encode_sample(1_700_000_000_000_000, 1_700_000_000_000_123, value)
        decoded = wire.decode(message)
        self.assertEqual(decoded, Sample(1_700_000_000_000_000, 1_700_000_000_000_123, value))
        self.assertIsInstance(decoded.value["pos"], Vec2)
        self.assertIsInstance(decoded.value["box"], Box)
        self.assertIsInstance(decoded.value["age"], Duration)
        self.assertIsInstance(decoded.value["n"], int)
        self.assertNotIsInstance(decoded.value["n"], Duration)
        self.assertEqual(wire.decode(wire.encode_end(42)), End(42))

    def test_the_header_and_packed_floats_are_as_documented(self):
        message = wire.encode_sample(5, 7, [1.0, 2.0])
        self.assertEqual(message[:5], b"KPL\x02S")
        self.assertEqual(struct.unpack_from("<qq", message, 5), (5, 7))
        self.assertEqual(message[21:], b"F" + struct.pack("<I2d", 2, 1.0, 2.0))
        # Not packed: an empty list, a list with an int, a list of vectors.
        self.assertEqual(wire.encode_value([]), b"l" + struct.pack("<I", 0))
        self.assertEqual(wire.encode_value([1.0, 2])[:1], b"l")
        # Packed from arrays and other buffers of doubles too.
        self.assertEqual(wire.encode_value(array.array("d", [1.0, 2.0])), wire.encode_value([1.0, 2.0]))
        self.assertEqual(wire.encode_value(memoryview(array.array("d", [3.0]))), wire.encode_value([3.0]))
        self.assertEqual(wire.encode_value(datetime.timedelta(seconds=2)), wire.encode_value(Duration(2_000_000)))
        self.assertEqual(wire.encode_end(3), b"KPL\x02E" + struct.pack("<Q", 3))
        # The symbol goes first, as KPL writes it.
        self.assertEqual(wire.encode_value({"x": 1, "id": "a"})[5:7], b"\x02\x00")

    def test_the_documented_decoder_reads_what_the_package_writes(self):
        decode = documented_decoder()
        rng = random.Random(16)
        for _ in range(500):
            value = random_value(rng)
            message = wire.encode_sample(rng.randint(-(2**63), 2**63 - 1), 0, value)
            kind, valid, available, decoded = decode(message)
            self.assertEqual((kind, available), ("sample", 0))
            self.assertEqual(decoded, plain(value))
            self.assertEqual(wire.decode(message).value, value)

    def test_version_one_is_read(self):
        message = b"KPL\x01S" + struct.pack("<qq", 1, 2) + b"r" + struct.pack("<d", 0.5)
        self.assertEqual(wire.decode(message), Sample(1, 2, 0.5))

    def test_bad_bytes_are_wire_errors(self):
        good = wire.encode_sample(1, 2, {"id": "a", "v": [1.0, 2.0], "s": "text", "l": [True, 3]})
        for n in range(len(good)):
            with self.assertRaises(WireError, msg=f"cut at {n}"):
                wire.decode(good[:n])
        cases = {
            "not KPL": b"JSON{}",
            "a newer version": b"KPL\x03S" + bytes(17),
            "an unknown kind": b"KPL\x02X" + bytes(17),
            "an unknown tag": b"KPL\x02S" + bytes(16) + b"?",
            "bytes after the value": good + b"t",
            "NaN": b"KPL\x02S" + bytes(16) + b"r" + struct.pack("<d", math.nan),
            "infinity, packed": b"KPL\x02S" + bytes(16) + b"F" + struct.pack("<I2d", 2, 1.0, math.inf),
            "a count beyond the bytes": b"KPL\x02S" + bytes(16) + b"l" + struct.pack("<I", 2**32 - 1),
            "a packed count beyond the bytes": b"KPL\x02S" + bytes(16) + b"F" + struct.pack("<I", 2**32 - 1),
            "not UTF-8": b"KPL\x02S" + bytes(16) + b"s" + struct.pack("<I", 1) + b"\xff",
            "nested too deep": b"KPL\x02S" + bytes(16) + (b"l" + struct.pack("<I", 1)) * 200 + b"t",
            "an end of the wrong length": b"KPL\x02E" + bytes(9),
        }
        for what, payload in cases.items():
            with self.assertRaises(WireError, msg=what):
                wire.decode(payload)

    def test_random_bytes_never_raise_anything_else(self):
        rng = random.Random(7)
        good = wire.encode_sample(1, 2, random_value(random.Random(3)))
        for _ in range(3000):
            payload = bytearray(good)
            for _ in range(rng.randint(1, 4)):
                payload[rng.randrange(len(payload))] = rng.randrange(256)
            try:
                wire.decode(bytes(payload))
            except WireError:
                pass

    def test_values_without_a_kpl_value_are_refused(self):
        for value in [None, object(), math.nan, [1.0, math.inf], 2**63, {1: "x"}, b"bytes"]:
            with self.assertRaises(WireError, msg=repr(value)):
                wire.encode_sample(0, 0, value)
        with self.assertRaises(WireError):
            wire.encode_sample(1.5, 0, 1)
        deep = True
        for _ in range(200):
            deep = [deep]
        with self.assertRaises(WireError):
            wire.encode_value(deep)


class Keys(unittest.TestCase):
    def test_names_become_key_chunks_as_documented(self):
        self.assertEqual(keys.chunk("my spec"), "my%20spec")
        self.assertEqual(keys.chunk(""), "%")
        self.assertEqual(keys.chunk("a-b_c.d"), "a-b_c.d")
        self.assertEqual(keys.chunk("wärme/*"), "w%C3%A4rme%2F%2A")
        self.assertEqual(keys.stream("python", "too_hot"), "kpl/default/python/too_hot")
        self.assertEqual(keys.stream("s", "link", "changes", "field 1"), "kpl/field%201/s/link/changes")
        self.assertEqual(keys.streams("two_hosts"), "kpl/default/two_hosts/**")


class Envelopes(unittest.TestCase):
    SECRET = bytes(range(32))

    def test_sealed_envelopes_open_with_the_secret_only(self):
        key, payload = "kpl/default/s/p", wire.encode_sample(1, 1, 2.0)
        sealed = envelope.seal(key, payload, "station", 0xFEED, 3, self.SECRET)
        self.assertEqual(len(sealed), 22 + len("station") + 32)
        opened = envelope.open_(sealed, key, payload, self.SECRET)
        self.assertEqual(opened, envelope.Envelope("station", 0xFEED, 3, False, True))
        refused = {
            "another secret": (sealed, key, payload, bytes(32)),
            "another key": (sealed, "kpl/default/s/q", payload, self.SECRET),
            "another payload": (sealed, key, wire.encode_sample(1, 1, 3.0), self.SECRET),
            "no secret": (sealed, key, payload, None),
            "no envelope": (None, key, payload, self.SECRET),
            "untagged": (envelope.seal(key, payload, "station", 1, 3), key, payload, self.SECRET),
            "cut short": (sealed[:30], key, payload, self.SECRET),
        }
        for what, args in refused.items():
            with self.assertRaises(envelope.EnvelopeError, msg=what):
                envelope.open_(*args)
        plain_envelope = envelope.seal(key, payload, "a", 1, 0, unfinished=True)
        self.assertEqual(envelope.open_(plain_envelope, key, payload), envelope.Envelope("a", 1, 0, True, False))

    def test_sequence_numbers_count_gaps_and_refuse_replays(self):
        seq = _Sequence()
        e = lambda inc, n: envelope.Envelope("a", inc, n)  # noqa: E731
        self.assertEqual(seq.accept(e(1, 0), False), (0, False))
        self.assertEqual(seq.accept(e(1, 3), False), (2, False))
        self.assertIsInstance(seq.accept(e(1, 3), False), str)
        self.assertEqual(seq.accept(e(2, 0), False), (0, True))
        # A run of the producer seen before goes on (messages are never shut out) ...
        self.assertEqual(seq.accept(e(1, 9), False), (5, False))
        # ... and what it sent is still refused when it comes again.
        self.assertIsInstance(seq.accept(e(1, 0), False), str)
        self.assertEqual(seq.accept(e(2, 1), True), (0, False))
        self.assertIsInstance(seq.accept(e(2, 1), True), str)
        self.assertEqual(seq.lost(), 7)

    def test_a_forged_sequence_number_never_shuts_the_producer_out(self):
        seq = _Sequence()
        e = lambda inc, n: envelope.Envelope("a", inc, n)  # noqa: E731
        for n in range(10):
            seq.accept(e(1, n), False)
        seq.accept(e(1, 2**64 - 2), False)
        seq.accept(e(99, 5), False)
        for n in range(10, 500):
            self.assertIsInstance(seq.accept(e(1, n), False), tuple, n)
        self.assertIsInstance(seq.accept(e(1, 300), False), str)

    def test_the_secret_is_read_from_a_keys_folder(self):
        import tempfile

        with tempfile.TemporaryDirectory() as folder:
            (Path(folder) / "secret").write_text(self.SECRET.hex() + "\n")
            self.assertEqual(envelope.read_secret(folder), self.SECRET)
            (Path(folder) / "secret").write_text("abcd\n")
            with self.assertRaises(envelope.EnvelopeError):
                envelope.read_secret(folder)


if __name__ == "__main__":
    unittest.main()
