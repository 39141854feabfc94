"""Checks the Foxglove views of a KPL MCAP recording with Foxglove's own schemas, as a Foxglove
user's tools would read them (tests/view.rs runs this):

    python tests/foxglove_mcap.py RECORDING.mcap

Reads the file with the `mcap` Python package. For every channel written for viewers (metadata
`kpl.view`): the schema is one of Foxglove's well-known schemas in protobuf, its descriptor set
defines the message as the `foxglove-schemas-protobuf` package does (the same fields, numbers and
types), and every message parses with that package's class without unknown fields and
serializes back to the same bytes. Then what the views say is compared with the samples of the
same file: each scene update of a level has one entity per object of the stream's sample at that
valid time, with its symbol, position, and hollow when predicted; each point cloud as many points
as the percepts; each log is an episode of its monitor.

Prints a JSON report on standard output; exits 1 on the first problem.
"""

import json
import struct
import sys
from collections import defaultdict

from google.protobuf import descriptor_pb2, unknown_fields
from mcap.reader import make_reader

import foxglove_schemas_protobuf.FrameTransforms_pb2 as FrameTransforms
import foxglove_schemas_protobuf.Log_pb2 as Log
import foxglove_schemas_protobuf.PointCloud_pb2 as PointCloud
import foxglove_schemas_protobuf.SceneUpdate_pb2 as SceneUpdate

CLASSES = {
    "foxglove.SceneUpdate": SceneUpdate.SceneUpdate,
    "foxglove.PointCloud": PointCloud.PointCloud,
    "foxglove.Log": Log.Log,
    "foxglove.FrameTransforms": FrameTransforms.FrameTransforms,
}


def fail(message):
    print(message, file=sys.stderr)
    sys.exit(1)


def fields_of(descriptor):
    """(name, number, type, label, type name) of each field of a message descriptor."""
    return sorted(
        (f.name, f.number, f.type, f.label, f.type_name.lstrip("."))
        for f in descriptor.field
    )


def check_schema(schema):
    """The schema's descriptor set defines each message type as Foxglove's package does."""
    if schema.encoding != "protobuf":
        fail(f"{schema.name}: schema encoding {schema.encoding}")
    cls = CLASSES.get(schema.name)
    if cls is None:
        fail(f"{schema.name}: not a schema this check knows")
    files = descriptor_pb2.FileDescriptorSet.FromString(schema.data)
    ours = {}
    for file in files.file:
        for message in file.message_type:
            ours[f"{file.package}.{message.name}"] = message
    checked = []
    pending = [cls.DESCRIPTOR]
    while pending:
        desc = pending.pop()
        if desc.full_name in checked:
            continue
        checked.append(desc.full_name)
        reference = descriptor_pb2.DescriptorProto()
        desc.CopyToProto(reference)
        if desc.full_name not in ours:
            fail(f"{schema.name}: the schema lacks {desc.full_name}")
        if fields_of(ours[desc.full_name]) != fields_of(reference):
            fail(f"{schema.name}: {desc.full_name} differs from foxglove-schemas-protobuf's")
        for field in desc.fields:
            if field.message_type is not None and field.message_type.full_name.startswith("foxglove."):
                pending.append(field.message_type)
    return checked


def no_unknown_fields(message, where):
    if len(unknown_fields.UnknownFieldSet(message)) > 0:
        fail(f"{where}: fields that {message.DESCRIPTOR.full_name} does not have")
    for field, value in message.ListFields():
        if field.type == field.TYPE_MESSAGE:
            repeated = field.is_repeated if hasattr(field, "is_repeated") else field.label == field.LABEL_REPEATED
            values = value if repeated else [value]
            for v in values:
                no_unknown_fields(v, where)


def main(path):
    report = {"channels": {}, "checked_types": [], "compared": defaultdict(int)}
    samples = defaultdict(dict)  # stream -> valid -> values (a monitor may report several at once)
    views = []
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        summary = reader.get_summary()
        for schema in summary.schemas.values():
            if schema.encoding == "protobuf":
                for name in check_schema(schema):
                    if name not in report["checked_types"]:
                        report["checked_types"].append(name)
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            if "kpl.view" not in channel.metadata:
                body = json.loads(message.data)
                samples[channel.topic].setdefault(body["valid"], []).append(body["value"])
                continue
            cls = CLASSES[schema.name]
            parsed = cls.FromString(message.data)
            where = f"{channel.topic} message {message.sequence}"
            no_unknown_fields(parsed, where)
            if parsed.SerializeToString(deterministic=True) != message.data:
                fail(f"{where}: does not serialize back to the same bytes")
            info = report["channels"].setdefault(
                channel.topic, {"schema": schema.name, "shows": channel.metadata["kpl.view"], "messages": 0}
            )
            info["messages"] += 1
            views.append((channel, schema.name, message, parsed))

    for channel, schema, message, parsed in views:
        stream = channel.metadata["kpl.view"]
        valid = message.publish_time // 1000
        if stream == "scene":
            continue
        values = samples[stream].get(valid)
        if values is None:
            fail(f"{channel.topic}: a view at {valid} us, but no sample of {stream} then")
        value = values[-1]
        if schema == "foxglove.SceneUpdate":
            objects = {o["id"]: o for o in value}
            entities = {e.id: e for e in parsed.entities}
            if sorted(entities) != sorted(objects):
                fail(f"{channel.topic} at {valid}: entities {sorted(entities)}, objects {sorted(objects)}")
            for symbol, entity in entities.items():
                o = objects[symbol]
                cube = entity.cubes[0]
                if abs(cube.pose.position.x - o["pos"][0]) > 1e-9 or abs(cube.pose.position.y - o["pos"][1]) > 1e-9:
                    fail(f"{channel.topic} at {valid}: {symbol} is drawn at another place")
                hollow = cube.color.a < 0.5
                if hollow == o.get("measured", True):
                    fail(f"{channel.topic} at {valid}: {symbol} measured {o.get('measured')} but drawn hollow {hollow}")
                if not any(t.text.startswith(symbol) for t in entity.texts):
                    fail(f"{channel.topic} at {valid}: {symbol} has no label")
                if entity.timestamp.seconds * 1_000_000 + entity.timestamp.nanos // 1000 != valid:
                    fail(f"{channel.topic} at {valid}: entity timestamp {entity.timestamp}")
            report["compared"]["objects"] += len(entities)
        elif schema == "foxglove.PointCloud":
            n = len(parsed.data) // parsed.point_stride
            if n != len(value):
                fail(f"{channel.topic} at {valid}: {n} points, {len(value)} percepts")
            for i, p in enumerate(value):
                x, y, _ = struct.unpack_from("<fff", parsed.data, i * parsed.point_stride)
                if abs(x - p["pos"][0]) > 1e-2 or abs(y - p["pos"][1]) > 1e-2:
                    fail(f"{channel.topic} at {valid}: point {i} is not percept {p['id']}")
            report["compared"]["points"] += n
        elif schema == "foxglove.Log":
            # Every episode the monitor reported at that valid time (two overtakes may start at once).
            episodes = [e for v in values for e in (v if isinstance(v, list) else [v])]
            if not any(e.get("verdict") == (parsed.level == 2) and all(v in parsed.message for k, v in e.items() if k not in ("verdict", "start", "end")) for e in episodes):
                fail(f"{channel.topic} at {valid}: log {parsed.message!r} is none of {episodes}")
            report["compared"]["logs"] += 1
    report["compared"] = dict(report["compared"])
    print(json.dumps(report, sort_keys=True))


if __name__ == "__main__":
    main(sys.argv[1])
