"""rosbag2 recordings written by `rosbags` (a pure-Python ROS 2 library, not kpl), for tests/ros2.rs.

    python tests/rosbag2_oracle.py write BAG_DIR EXPECTED.jsonl --seed 7 --count 40
    python tests/rosbag2_oracle.py check EXPECTED.jsonl KPL.jsonl
    python tests/rosbag2_oracle.py read KPL_BAG_DIR TRACKS.jsonl
    python tests/rosbag2_oracle.py markers BAG_DIR --fcd FCD --start 100 --seconds 30
    python tests/rosbag2_oracle.py hash IN.mcap OUT.mcap [--flip]

`write` records a rosbag2 bag in MCAP (rosbags' writer: CDR messages, `ros2msg` schemas,
metadata.yaml) with random geometry_msgs/msg/PoseStamped messages on /robot/pose and random
visualization_msgs/msg/MarkerArray messages (up to 5 markers, every field filled, nested
sequences included) on /tracker/markers, and writes each message as rosbags holds it (its
dataclass as a JSON object, fixed arrays and byte sequences as lists) with its topic and time.
`check` compares kpl's JSON lines (`kpl convert BAG.mcap KPL.jsonl`) with them, in order: the
stream is the topic, `valid` and `available` the message's time in microseconds, and every
field equal (float32 fields to float32 precision). It exits 1 and says where on a difference.
`read` opens a bag that kpl wrote (`kpl convert TRACKS.jsonl BAG --spec specs/ros2/markers.kpl`)
with rosbags (AnyReader: metadata.yaml, the MCAP file, every message deserialized with its
type) and with mcap-ros2-support (its own reading of the `ros2msg` schemas and its CDR decoder),
and checks both against kpl's recording: one /kpl/cars MarkerArray and one /kpl/detections
Detection3DArray per sample of `onroad_car`, at its available time, `header.stamp` its valid
time, a marker per car (`ns` its symbol, `pose.position` its position, `scale.x` its size).
`markers` records, with rosbags' writer, what a ROS 2 tracker publishes on /tracker/markers (the
contract of specs/ros2/markers.kpl) for the vehicles of a SUMO recording (FCD): a MarkerArray per
time step, a marker per vehicle (`id` its track id, `pose.position` x and y, `scale.x` 5 m,
`header.stamp` the step's time from 2023-11-14T22:13:20Z), chunks compressed with zstd. It is
how specs/ros2/tracker/ was made; it prints the number of messages and markers as JSON.
`hash` copies an MCAP file of a bag (with the `mcap` package's reader and writer, records as
they are) and gives each CDR channel the type hash that `ros2 bag record` (Jazzy on) records in
its channel metadata, `topic_type_hash`: rosbags' RIHS01 hash of the channel's type, or with
`--flip` that hash with its last hex digit changed (a bag recorded with another definition of
the type). It prints the hashes by topic as JSON.
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


def default_msg(name):
    """A message of `name` with every field zero, empty or default."""
    _, fields = TS.fielddefs[name]

    def value(desc):
        kind, detail = desc
        if kind == 1:
            t = detail[0]
            return '' if t == 'string' else False if t == 'bool' else 0.0 if t.startswith('float') else 0
        if kind == 2:
            return default_msg(detail)
        inner, size = detail
        items = [value(inner) for _ in range(size if kind == 3 else 0)]
        if inner[0] == 1 and inner[1][0] in NP:
            return np.array(items, dtype=NP[inner[1][0]])
        return items

    return TS.types[name](**{f: value(d) for f, d in fields})


def fcd_frames(fcd, start, seconds):
    """(time, [(vehicle, x, y)]) of a SUMO FCD recording from `start` for `seconds`."""
    import gzip
    import xml.etree.ElementTree as ET
    frame, t = [], None
    with gzip.open(fcd) as f:
        for event, el in ET.iterparse(f, events=('start', 'end')):
            if event == 'start' and el.tag == 'timestep':
                t = float(el.get('time'))
            elif event == 'end' and el.tag == 'vehicle' and t is not None and t >= start:
                frame.append((el.get('id'), float(el.get('x')), float(el.get('y'))))
            elif event == 'end' and el.tag == 'timestep':
                if t is not None and t >= start:
                    yield t, frame
                frame = []
                el.clear()
                if t is not None and t >= start + seconds:
                    return


def markers(bag, fcd, start, seconds):
    from rosbags.rosbag2 import CompressionFormat, CompressionMode
    epoch = 1_700_000_000_000_000_000
    ty = 'visualization_msgs/msg/MarkerArray'
    ids, count, total = {}, 0, 0
    writer = Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP)
    writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
    with writer:
        conn = writer.add_connection('/tracker/markers', ty, typestore=TS)
        for t, vehicles in fcd_frames(fcd, start, seconds):
            ns = epoch + round((t - start) * 1e9)
            msg = default_msg(ty)
            for vehicle, x, y in vehicles:
                m = default_msg('visualization_msgs/msg/Marker')
                m.header.stamp.sec, m.header.stamp.nanosec = ns // 10**9, ns % 10**9
                m.header.frame_id = 'map'
                m.ns = 'tracker'
                m.id = ids.setdefault(vehicle, len(ids) + 1)
                m.type = 1
                m.pose.position.x, m.pose.position.y = x, y
                m.pose.orientation.w = 1.0
                m.scale.x, m.scale.y, m.scale.z = 5.0, 1.8, 1.5
                msg.markers.append(m)
            writer.write(conn, ns, TS.serialize_cdr(msg, ty))
            count += 1
            total += len(vehicles)
    print(json.dumps({'messages': count, 'markers': total, 'vehicles': len(ids)}))


def stamp_us(stamp):
    return stamp.sec * 1_000_000 + stamp.nanosec // 1000


def read(bag, tracks):
    from mcap_ros2.reader import read_ros2_messages
    from rosbags.highlevel import AnyReader

    samples = [json.loads(l) for l in Path(tracks).read_text().splitlines() if l]
    samples = [s for s in samples if s['stream'] == 'onroad_car']
    if not samples:
        sys.exit('no onroad_car samples in the recording')
    by_rosbags = {'/kpl/cars': [], '/kpl/detections': []}
    with AnyReader([Path(bag)]) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        want = {'/kpl/cars': 'visualization_msgs/msg/MarkerArray',
                '/kpl/detections': 'vision_msgs/msg/Detection3DArray'}
        if types != want:
            sys.exit(f'topics {types}, expected {want}')
        if reader.message_count != 2 * len(samples):
            sys.exit(f'metadata: {reader.message_count} messages, expected {2 * len(samples)}')
        for conn, t, raw in reader.messages():
            by_rosbags[conn.topic].append((t, reader.deserialize(raw, conn.msgtype)))
    by_mcap = {'/kpl/cars': [], '/kpl/detections': []}
    # A bag split into several files (`<bag>_0.mcap`, `<bag>_1.mcap`, ...): each in turn.
    files = sorted(Path(bag).glob('*.mcap'), key=lambda p: int(p.stem.rsplit('_', 1)[-1]))
    for file in files:
        for m in read_ros2_messages(str(file)):
            by_mcap[m.channel.topic].append((m.log_time_ns, m.ros_msg))
    for name, got in (('rosbags', by_rosbags), ('mcap-ros2-support', by_mcap)):
        for topic, messages in got.items():
            if len(messages) != len(samples):
                sys.exit(f'{name}: {len(messages)} messages on {topic}, {len(samples)} samples')
        for i, sample in enumerate(samples):
            cars = sample['value']
            (t, markers), (t2, detections) = got['/kpl/cars'][i], got['/kpl/detections'][i]
            where = f'{name}, sample {i + 1} at {sample["valid"]}'
            if t != sample['available'] * 1000 or t2 != t:
                sys.exit(f'{where}: log time {t}/{t2}, available {sample["available"]}')
            if len(markers.markers) != len(cars) or len(detections.detections) != len(cars):
                sys.exit(f'{where}: {len(markers.markers)} markers, {len(cars)} cars')
            for car, marker, det in zip(cars, markers.markers, detections.detections):
                checks = [
                    (marker.ns, car['id']), (det.id, car['id']),
                    (marker.header.frame_id, 'map'), (stamp_us(marker.header.stamp), sample['valid']),
                    (stamp_us(detections.header.stamp), sample['valid']),
                    (marker.pose.position.x, car['pos'][0]), (marker.pose.position.y, car['pos'][1]),
                    (marker.scale.x, car['size']), (marker.id, int(''.join(c for c in car['id'] if c.isdigit()))),
                    (det.bbox.center.position.x, car['pos'][0]), (det.bbox.size.x, car['size']),
                ]
                for have, expect in checks:
                    if have != expect:
                        sys.exit(f'{where}, {car["id"]}: {have!r} != {expect!r}')
    print(f'{len(samples)} samples, {2 * len(samples)} messages equal in rosbags and mcap-ros2-support')


def rehash(src, dst, flip):
    from mcap.reader import make_reader
    from mcap.writer import Writer as McapWriter

    hashes = {}
    with open(src, 'rb') as f, open(dst, 'wb') as out:
        reader = make_reader(f)
        writer = McapWriter(out)
        header = reader.get_header()
        writer.start(profile=header.profile, library='rosbag2_oracle.py')
        schemas, channels = {}, {}
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            if schema.id not in schemas:
                schemas[schema.id] = writer.register_schema(schema.name, schema.encoding, schema.data)
            if channel.id not in channels:
                metadata = dict(channel.metadata)
                if channel.message_encoding == 'cdr':
                    digest = TS.hash_rihs01(schema.name)
                    if flip:
                        digest = digest[:-1] + ('0' if digest[-1] != '0' else '1')
                    metadata['topic_type_hash'] = digest
                    hashes[channel.topic] = digest
                channels[channel.id] = writer.register_channel(
                    channel.topic, channel.message_encoding, schemas[schema.id], metadata)
            writer.add_message(channels[channel.id], message.log_time, message.data, message.publish_time,
                               message.sequence)
        writer.finish()
    print(json.dumps(hashes))


if __name__ == '__main__':
    if sys.argv[1] == 'hash':
        rehash(sys.argv[2], sys.argv[3], '--flip' in sys.argv[4:])
        sys.exit(0)
    if sys.argv[1] == 'read':
        read(sys.argv[2], sys.argv[3])
    elif sys.argv[1] == 'markers':
        args = sys.argv[3:]
        markers(Path(sys.argv[2]), args[args.index('--fcd') + 1], float(args[args.index('--start') + 1]),
                float(args[args.index('--seconds') + 1]))
    elif sys.argv[1] == 'write':
        args = sys.argv[2:]
        seed = int(args[args.index('--seed') + 1]) if '--seed' in args else 7
        count = int(args[args.index('--count') + 1]) if '--count' in args else 40
        write(Path(args[0]), args[1], seed, count)
    else:
        check(sys.argv[2], sys.argv[3])
