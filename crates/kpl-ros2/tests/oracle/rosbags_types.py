"""The type-hash and CDR oracle of `rosbags` (a pure-Python ROS 2 library, independent of rosidl).

    python rosbags_types.py MSG_ROOT KPL_MESSAGES OUT

MSG_ROOT is a folder of `<package>/<Name>.msg` or `<package>/msg/<Name>.msg` files (kpl's shipped
definitions and a user's). Every definition is registered in an empty rosbags type store, which
parses it with its own parser, and OUT gets `{"hashes": {type: RIHS01 hash}}` (rosbags'
`hash_rihs01`), the hashes rosidl wrote into the installed ROS 2 packages
(`<prefix>/share/<pkg>/msg/<Name>.json`, where the packages are installed), and the CDR checks:
KPL_MESSAGES are JSON lines `{"type", "json", "cdr"}` made by kpl; each is serialized by rosbags
from its JSON (bytes must be kpl's) and kpl's bytes deserialized by rosbags (fields must be the
JSON).
"""

import json
import math
import os
import sys
from pathlib import Path

import numpy
from rosbags.typesys import Stores, get_typestore, get_types_from_msg
from rosbags.typesys.base import Nodetype


def load(root):
    types = {}
    for path in sorted(Path(root).rglob("*.msg")):
        package = path.parent.parent.name if path.parent.name == "msg" else path.parent.name
        types.update(get_types_from_msg(path.read_text(), f"{package}/msg/{path.stem}"))
    store = get_typestore(Stores.EMPTY)
    store.register(types)
    return store, sorted(types)


def official_hashes():
    share = Path(sys.prefix) / "share"
    out = {}
    for path in share.glob("*/msg/*.json"):
        try:
            data = json.loads(path.read_text())
        except ValueError:
            continue
        for entry in data.get("type_hashes", []):
            out.setdefault(entry["type_name"], entry["hash_string"])
    return out


PLACEHOLDER = "structure_needs_at_least_one_member"


def from_json(store, name, value):
    cls = store.types[name]
    _, fields = store.fielddefs[name]
    args = {}
    for fname, desc in fields:
        # rosbags gives an empty message the placeholder field that is its one byte on the wire.
        args[fname] = 0 if fname == PLACEHOLDER else convert_in(store, desc, value[fname])
    return cls(**args)


NUMPY = {
    "bool": numpy.bool_, "byte": numpy.uint8, "char": numpy.uint8, "int8": numpy.int8, "uint8": numpy.uint8,
    "int16": numpy.int16, "uint16": numpy.uint16, "int32": numpy.int32, "uint32": numpy.uint32,
    "int64": numpy.int64, "uint64": numpy.uint64, "float32": numpy.float32, "float64": numpy.float64,
}


def convert_in(store, desc, v):
    kind, detail = desc
    if kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
        inner = detail[0]
        if inner[0] == Nodetype.BASE and inner[1][0] in NUMPY:
            return numpy.array([float("nan") if x is None else x for x in v], dtype=NUMPY[inner[1][0]])
        return [convert_in(store, inner, x) for x in v]
    if kind == Nodetype.NAME:
        return from_json(store, detail, v)
    if detail[0] in ("float32", "float64") and v is None:
        return float("nan")
    return v


def to_json(store, name, msg):
    _, fields = store.fielddefs[name]
    return {fname: convert_out(store, desc, getattr(msg, fname)) for fname, desc in fields if fname != PLACEHOLDER}


def convert_out(store, desc, v):
    kind, detail = desc
    if kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
        return [convert_out(store, detail[0], x) for x in v]
    if kind == Nodetype.NAME:
        return to_json(store, detail, v)
    base = detail[0]
    if base in ("float32", "float64"):
        f = float(v)
        return None if not math.isfinite(f) else f
    if base == "bool":
        return bool(v)
    if base == "string":
        return str(v)
    if base == "byte":
        # rosbags reads `byte` as int8 (ROS 1's meaning); in ROS 2 it is an octet, 0 to 255.
        return int(v) % 256
    return int(v)


def main():
    root, kpl_path, out_path = sys.argv[1], sys.argv[2], sys.argv[3]
    store, names = load(root)
    hashes = {name: store.hash_rihs01(name) for name in names}
    mismatches, checked = [], 0
    with open(kpl_path) as f:
        for line in f:
            case = json.loads(line)
            name = case["type"]
            want = bytes.fromhex(case["cdr"])
            got = bytes(store.serialize_cdr(from_json(store, name, case["json"]), name))
            if got != want:
                mismatches.append({"type": name, "way": "rosbags serialize", "kpl": case["cdr"], "rosbags": got.hex()})
            back = to_json(store, name, store.deserialize_cdr(want, name))
            if json.dumps(back, sort_keys=True) != json.dumps(case["json"], sort_keys=True):
                mismatches.append({"type": name, "way": "rosbags deserialize", "kpl": case["json"], "rosbags": back})
            checked += 1
    with open(out_path, "w") as out:
        json.dump({"hashes": hashes, "official": official_hashes(), "checked": checked,
                   "mismatch_count": len(mismatches), "mismatches": mismatches[:20]}, out)


if __name__ == "__main__":
    main()
