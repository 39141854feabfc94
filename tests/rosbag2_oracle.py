"""rosbag2 recordings written by `rosbags` (a pure-Python ROS 2 library, not kpl), for tests/ros2.rs.

    python tests/rosbag2_oracle.py write BAG_DIR EXPECTED.jsonl --seed 7 --count 40
    python tests/rosbag2_oracle.py check EXPECTED.jsonl KPL.jsonl

`write` records a rosbag2 bag in MCAP (rosbags' writer: CDR messages, `ros2msg` schemas,
metadata.yaml) with random geometry_msgs/msg/PoseStamped messages on /robot/pose and random
visualization_msgs/msg/MarkerArray messages (up to 5 markers, every field filled, nested
sequences included) on /tracker/markers, and writes each message as rosbags holds it (its
dataclass as a JSON object, fixed arrays and byte sequences as lists) with its topic and time.
`check` compares kpl's JSON lines (`kpl convert BAG.mcap KPL.jsonl`) with them, in order: the
stream is the topic, `valid` and `available` the message's time in microseconds, and every
field equal (float32 fields to float32 precision). It exits 1 and says where on a difference.
"""

import json
import math
import random
import sys
from pathlib import Path

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

TS = get_typestore(Stores.LATEST)
INTS = {
    'int8': (-128, 127), 'uint8': (0, 255), 'byte': (0, 255), 'char': (0, 255),
    'int16': (-2**15, 2**15 - 1), 'uint16': (0, 2**16 - 1), 'int32': (-2**31, 2**31 - 1),
    'uint32': (0, 2**32 - 1), 'int64': (-2**63, 2**63 - 1), 'uint64': (0, 2**64 - 1),
}
NP = {'int8': np.int8, 'uint8': np.uint8, 'byte': np.uint8, 'char': np.uint8, 'int16': np.int16,
      'uint16': np.uint16, 'int32': np.int32, 'uint32': np.uint32, 'int64': np.int64,
      'uint64': np.uint64, 'float32': np.float32, 'float64': np.float64, 'bool': np.bool_}


def base(rng, name):
    if name in INTS:
        lo, hi = INTS[name]
        return rng.randint(lo, hi)
    if name == 'float32':
        return float(np.float32(rng.uniform(-1e4, 1e4)))
    if name == 'float64':
        return rng.uniform(-1e6, 1e6)
    if name == 'bool':
        return rng.random() < 0.5
    if name == 'string':
        return ''.join(rng.choice('abcxyz _/.-0123') for _ in range(rng.randint(0, 12)))
    raise ValueError(name)


def random_field(rng, desc, depth):
    kind, detail = desc
    if kind == 1:  # BASE
        return base(rng, detail[0])
    if kind == 2:  # NAME
        return random_msg(rng, detail, depth + 1)
    inner, size = detail
    count = size if kind == 3 else rng.randint(0, 3 if depth > 1 else 5)
    items = [random_field(rng, inner, depth) for _ in range(count)]
    if inner[0] == 1 and inner[1][0] in NP:
        return np.array(items, dtype=NP[inner[1][0]])
    return items


def random_msg(rng, name, depth=0):
    _, fields = TS.fielddefs[name]
    cls = TS.types[name]
    return cls(**{f: random_field(rng, d, depth) for f, d in fields})


def as_json(value):
    if isinstance(value, np.ndarray):
        return [as_json(v) for v in value.tolist()]
    if isinstance(value, (list, tuple)):
        return [as_json(v) for v in value]
    if hasattr(value, '__msgtype__'):
        _, fields = TS.fielddefs[value.__msgtype__]
        return {name: as_json(getattr(value, name)) for name, _ in fields}
    if isinstance(value, (np.generic,)):
        return value.item()
    return value


def write(bag, expected, seed, count):
    rng = random.Random(seed)
    topics = [('/robot/pose', 'geometry_msgs/msg/PoseStamped'),
              ('/tracker/markers', 'visualization_msgs/msg/MarkerArray')]
    lines = []
    with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conns = [(topic, ty, writer.add_connection(topic, ty, typestore=TS)) for topic, ty in topics]
        t = 1_700_000_000_000_000_000
        for _ in range(count):
            topic, ty, conn = rng.choice(conns)
            t += rng.randint(1, 50_000_000)
            msg = random_msg(rng, ty)
            writer.write(conn, t, TS.serialize_cdr(msg, ty))
            lines.append({'stream': topic, 'time_us': t // 1000, 'value': as_json(msg)})
    with open(expected, 'w') as f:
        for line in lines:
            f.write(json.dumps(line) + '\n')


def same(a, b, path):
    if isinstance(a, dict) and isinstance(b, dict):
        if set(a) != set(b):
            return f'{path}: fields {sorted(a)} != {sorted(b)}'
        for k in a:
            d = same(a[k], b[k], f'{path}.{k}')
            if d:
                return d
        return None
    if isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            return f'{path}: {len(a)} elements != {len(b)}'
        for i, (x, y) in enumerate(zip(a, b)):
            d = same(x, y, f'{path}[{i}]')
            if d:
                return d
        return None
    if isinstance(a, float) or isinstance(b, float):
        if isinstance(a, bool) or isinstance(b, bool) or a is None or b is None:
            return f'{path}: {a!r} != {b!r}'
        return None if math.isclose(a, b, rel_tol=1e-7, abs_tol=0.0) else f'{path}: {a!r} != {b!r}'
    return None if a == b and type(a) is type(b) else f'{path}: {a!r} != {b!r}'


def check(expected, got):
    want = [json.loads(l) for l in Path(expected).read_text().splitlines() if l]
    have = [json.loads(l) for l in Path(got).read_text().splitlines() if l]
    if len(want) != len(have):
        sys.exit(f'{len(have)} lines from kpl, {len(want)} messages in the bag')
    for i, (w, h) in enumerate(zip(want, have)):
        if h['stream'] != w['stream'] or h['valid'] != w['time_us'] or h['available'] != w['time_us']:
            sys.exit(f'line {i + 1}: {h["stream"]} at {h["valid"]}/{h["available"]}, '
                     f'the bag has {w["stream"]} at {w["time_us"]}')
        d = same(w['value'], h['value'], f'line {i + 1} ({w["stream"]})')
        if d:
            sys.exit(d)
    print(f'{len(want)} messages equal')


if __name__ == '__main__':
    if sys.argv[1] == 'write':
        args = sys.argv[2:]
        seed = int(args[args.index('--seed') + 1]) if '--seed' in args else 7
        count = int(args[args.index('--count') + 1]) if '--count' in args else 40
        write(Path(args[0]), args[1], seed, count)
    else:
        check(sys.argv[2], sys.argv[3])
