"""The CDR oracle: ROS 2's own serialization (rclpy.serialization, the C type support of the
message wheels) against kpl-ros2's codec, both ways.

    python rclpy_cdr.py KPL_MESSAGES OUT COUNT SEED

KPL_MESSAGES is JSON lines `{"type": "pkg/msg/Name", "json": {...}, "cdr": "<hex>", "pads": [[at,
len], ...]}` written by kpl's codec (`pads`: where its padding bytes are; Fast-CDR leaves them as its
buffer had them, kpl writes zeros, so they are zeroed before comparing). For each, this script builds the message from its JSON with rclpy's generated class and
serializes it (the bytes must equal kpl's), and deserializes kpl's bytes (the fields must equal the
JSON). Then it makes COUNT random messages of every type it was given, serialized by rclpy, and
writes them to OUT as the same JSON lines for kpl to decode. The last line of OUT is the summary
`{"summary": {"checked": N, "mismatches": [...]}}`.
"""

import array
import importlib
import json
import math
import random
import struct
import sys

import numpy
from rclpy.serialization import deserialize_message, serialize_message
from rosidl_parser import definition as d

INT_RANGES = {
    "int8": (-(2**7), 2**7 - 1),
    "int16": (-(2**15), 2**15 - 1),
    "int32": (-(2**31), 2**31 - 1),
    "int64": (-(2**63), 2**63 - 1),
    "uint8": (0, 2**8 - 1),
    "uint16": (0, 2**16 - 1),
    "uint32": (0, 2**32 - 1),
    "uint64": (0, 2**64 - 1),
    "char": (0, 2**8 - 1),
}
ALPHABET = "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789 _-/.:é漢🙂"


def message_class(name):
    package, _, typename = name.split("/")
    return getattr(importlib.import_module(f"{package}.msg"), typename)


def fields(cls):
    return list(zip(cls.get_fields_and_field_types().keys(), cls.SLOT_TYPES))


def nested_class(t):
    return message_class("/".join(t.namespaces + [t.name]))


# ---- JSON -> message (kpl's values into rclpy's classes) ----


def set_from_json(cls, value):
    msg = cls()
    for name, t in fields(cls):
        setattr(msg, name, convert_in(t, value[name]))
    return msg


def convert_in(t, v):
    if isinstance(t, d.AbstractNestedType):
        return [convert_in(t.value_type, x) for x in v]
    if isinstance(t, d.NamespacedType):
        return set_from_json(nested_class(t), v)
    if isinstance(t, d.BasicType) and t.typename == "octet":
        return bytes([v])
    if isinstance(t, d.BasicType) and t.typename in ("float", "double"):
        return float("nan") if v is None else float(v)
    return v


# ---- message -> JSON ----


def to_json(msg):
    return {name: convert_out(t, getattr(msg, name)) for name, t in fields(type(msg))}


def convert_out(t, v):
    if isinstance(t, d.AbstractNestedType):
        return [convert_out(t.value_type, x) for x in v]
    if isinstance(t, d.NamespacedType):
        return to_json(v)
    if isinstance(t, d.BasicType):
        if t.typename == "octet":
            return v[0] if isinstance(v, (bytes, bytearray)) else int(v)
        if t.typename in ("float", "double"):
            f = float(v)
            return None if not math.isfinite(f) else f
        if t.typename == "boolean":
            return bool(v)
        return int(v)
    return str(v)


# ---- random messages ----


def random_float(rng, double):
    if double:
        while True:
            f = struct.unpack("<d", rng.randbytes(8))[0]
            if math.isfinite(f):
                return f
    while True:
        f = struct.unpack("<f", rng.randbytes(4))[0]
        if math.isfinite(f):
            return f


def random_value(rng, t, depth):
    if isinstance(t, d.Array):
        return [random_value(rng, t.value_type, depth) for _ in range(t.size)]
    if isinstance(t, d.BoundedSequence):
        return [random_value(rng, t.value_type, depth) for _ in range(rng.randint(0, min(3, t.maximum_size)))]
    if isinstance(t, d.UnboundedSequence):
        n = rng.randint(0, 12) if isinstance(t.value_type, d.BasicType) else rng.randint(0, 2 if depth < 3 else 0)
        return [random_value(rng, t.value_type, depth) for _ in range(n)]
    if isinstance(t, d.NamespacedType):
        return random_message(rng, nested_class(t), depth + 1)
    if isinstance(t, d.AbstractString):
        limit = getattr(t, "maximum_size", 12)
        s = "".join(rng.choice(ALPHABET) for _ in range(rng.randint(0, 12)))
        while len(s.encode()) > limit:
            s = s[:-1]
        return s
    name = t.typename
    if name == "boolean":
        return rng.random() < 0.5
    if name == "octet":
        return bytes([rng.randint(0, 255)])
    if name in ("float", "double"):
        return random_float(rng, name == "double")
    lo, hi = INT_RANGES[name]
    return rng.randint(lo, hi)


def random_message(rng, cls, depth=0):
    msg = cls()
    for name, t in fields(cls):
        setattr(msg, name, random_value(rng, t, depth))
    return msg


def same(a, b):
    """JSON equality with floats compared exactly (and NaN as null on both sides)."""
    return json.dumps(a, sort_keys=True) == json.dumps(b, sort_keys=True)


def main():
    kpl_path, out_path, count, seed = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
    mismatches = []
    checked = 0
    max_extra = 0
    types = []
    with open(kpl_path) as f:
        for line in f:
            case = json.loads(line)
            name = case["type"]
            if name not in types:
                types.append(name)
            cls = message_class(name)
            want = bytes.fromhex(case["cdr"])
            got = bytearray(serialize_message(set_from_json(cls, case["json"])))
            # Fast-CDR leaves padding bytes as its buffer had them; kpl writes zeros there.
            for at, length in case.get("pads", []):
                if at + length <= len(got):
                    got[at:at + length] = bytes(length)
            # rmw_fastrtps sizes the buffer by its estimate of the size, which can exceed the
            # message: bytes past the end of the message are not part of it.
            extra = len(got) - len(want)
            max_extra = max(max_extra, extra)
            if extra < 0 or got[: len(want)] != want:
                mismatches.append({"type": name, "way": "rclpy serialize", "json": case["json"], "kpl": case["cdr"], "rclpy": bytes(got).hex()})
            back = to_json(deserialize_message(want, cls))
            if not same(back, case["json"]):
                mismatches.append({"type": name, "way": "rclpy deserialize", "kpl": case["json"], "rclpy": back})
            checked += 1
    rng = random.Random(seed)
    with open(out_path, "w") as out:
        for name in types:
            cls = message_class(name)
            for _ in range(count):
                msg = random_message(rng, cls)
                out.write(json.dumps({"type": name, "json": to_json(msg), "cdr": serialize_message(msg).hex()}) + "\n")
        out.write(json.dumps({"summary": {"checked": checked, "mismatches": mismatches[:20], "mismatch_count": len(mismatches), "max_extra": max_extra}}) + "\n")


if __name__ == "__main__":
    main()
