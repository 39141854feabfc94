"""A ROS 2 tracker node speaking rmw_zenoh, without ROS, for tests/ros2.rs.

    python tests/ros2_node.py --listen tcp/127.0.0.1:PORT --fcd FCD --start 100 --seconds 20 --out RESULT

It opens a zenoh session that listens on the endpoint (the router kpl connects to), declares a
node `/tracker` and a publisher of /tracker/markers exactly as rmw_zenoh does (keys, liveliness
tokens and the 33-byte attachment from zenoh-ros2-sdk, the type hash rosidl wrote into the
visualization_msgs package, CDR from rclpy), and publishes the vehicles of a SUMO recording (FCD)
in real time as MarkerArrays: one marker per vehicle, `id` its track id, `pose.position` x and y,
`scale.x` its length, `header.stamp` the time it was published. It subscribes to /kpl/cars
(MarkerArray, decoded by rclpy) and /kpl/detections (vision_msgs/Detection3DArray, decoded by
rosbags from kpl's shipped definitions, as there is no rclpy wheel of vision_msgs). At the end it
sends three bad messages (no attachment, one of a publisher declared with another type hash, truncated CDR), takes its publisher
away, waits for kpl to finish, and writes RESULT: what it received and the ROS 2 graph it saw.
"""

import argparse
import gzip
import json
import os
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import zenoh
from builtin_interfaces.msg import Time as TimeMsg
from geometry_msgs.msg import Point
from rclpy.serialization import deserialize_message, serialize_message
from rosbags.typesys import Stores, get_typestore, get_types_from_msg
from visualization_msgs.msg import Marker, MarkerArray
from zenoh_ros2_sdk.attachment import Attachment
from zenoh_ros2_sdk.entity import EndpointEntity, EntityKind, NodeEntity
from zenoh_ros2_sdk.keyexpr import endpoint_liveliness_keyexpr, node_liveliness_keyexpr, topic_keyexpr
from zenoh_ros2_sdk.qos import QosProfile
from zenoh_ros2_sdk.utils import ros2_to_dds_type

ROOT = Path(__file__).resolve().parent.parent
MARKER_ARRAY = "visualization_msgs/msg/MarkerArray"
DETECTIONS = "vision_msgs/msg/Detection3DArray"
VEHICLE_LENGTH = 5.0  # SUMO's default vehicle type


def rosidl_hash(type_name):
    package, _, name = type_name.split("/")
    data = json.loads((Path(sys.prefix) / "share" / package / "msg" / f"{name}.json").read_text())
    return next(h["hash_string"] for h in data["type_hashes"] if h["type_name"] == type_name)


def vision_store():
    store = get_typestore(Stores.LATEST)
    types = {}
    for path in (ROOT / "crates/kpl-ros2/msgs/vision_msgs").glob("*.msg"):
        types.update(get_types_from_msg(path.read_text(), f"vision_msgs/msg/{path.stem}"))
    store.register(types)
    return store


def frames(fcd, start, seconds):
    """(time, [(vehicle, x, y)]) of the recording from `start` for `seconds`."""
    frame, t = [], None
    with gzip.open(fcd) as f:
        for event, el in ET.iterparse(f, events=("start", "end")):
            if event == "start" and el.tag == "timestep":
                t = float(el.get("time"))
            elif event == "end" and el.tag == "vehicle" and t is not None and t >= start:
                frame.append((el.get("id"), float(el.get("x")), float(el.get("y"))))
            elif event == "end" and el.tag == "timestep":
                if t is not None and t >= start:
                    yield t, frame
                frame = []
                el.clear()
                if t is not None and t >= start + seconds:
                    return


def stamp(ns):
    return TimeMsg(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--listen", required=True)
    ap.add_argument("--fcd", required=True)
    ap.add_argument("--start", type=float, default=100.0)
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--out", required=True)
    ap.add_argument("--wait-kpl", type=float, default=30.0, help="how long to wait for kpl's node before publishing")
    args = ap.parse_args()

    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("listen/endpoints", json.dumps([args.listen]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    session = zenoh.open(conf)
    zid = str(session.zid())

    node = NodeEntity(domain_id=0, session_id=zid, node_id=0, node_name="tracker", namespace="/")
    markers_hash = rosidl_hash(MARKER_ARRAY)
    dds = ros2_to_dds_type(MARKER_ARRAY)
    qos = QosProfile().encode()
    pub_entity = EndpointEntity(node=node, entity_id=1, kind=EntityKind.PUBLISHER, name="/tracker/markers",
                                dds_type_name=dds, type_hash=markers_hash, qos=qos)
    sub_entity = EndpointEntity(node=node, entity_id=2, kind=EntityKind.SUBSCRIPTION, name="/kpl/cars",
                                dds_type_name=dds, type_hash=markers_hash, qos=qos)
    node_token = session.liveliness().declare_token(node_liveliness_keyexpr(node))
    sub_token = session.liveliness().declare_token(endpoint_liveliness_keyexpr(sub_entity))

    result = {"cars": [], "detections": [], "bad_attachments": 0, "graph": [], "cars_hash_ok": True,
              "detections_hash": None, "published_frames": 0, "published_markers": 0}
    store = vision_store()

    def on_cars(sample):
        a = sample.attachment
        try:
            Attachment.from_bytes(a.to_bytes()) if a is not None else None
        except ValueError:
            a = None
        if a is None or len(a.to_bytes()) != 33:
            result["bad_attachments"] += 1
        msg = deserialize_message(sample.payload.to_bytes(), MarkerArray)
        for m in msg.markers:
            result["cars"].append({"ns": m.ns, "id": m.id, "x": m.pose.position.x, "y": m.pose.position.y,
                                   "stamp": m.header.stamp.sec * 1_000_000 + m.header.stamp.nanosec // 1000,
                                   "frame": m.header.frame_id, "length": m.scale.x})

    def on_detections(sample):
        result["detections_hash"] = str(sample.key_expr).rsplit("/", 1)[-1]
        if sample.attachment is None or len(sample.attachment.to_bytes()) != 33:
            result["bad_attachments"] += 1
        msg = store.deserialize_cdr(sample.payload.to_bytes(), DETECTIONS)
        for d in msg.detections:
            result["detections"].append({"id": d.id, "x": float(d.bbox.center.position.x), "y": float(d.bbox.center.position.y)})

    cars_sub = session.declare_subscriber(topic_keyexpr(0, "/kpl/cars", dds, markers_hash), on_cars)
    det_sub = session.declare_subscriber(f"0/kpl/detections/{ros2_to_dds_type(DETECTIONS)}/*", on_detections)

    # Wait until kpl's subscription of /tracker/markers is in the graph.
    deadline = time.time() + args.wait_kpl
    while time.time() < deadline:
        replies = list(session.liveliness().get("@ros2_lv/0/**/MS/**/%tracker%markers/**", timeout=1.0))
        if any(r.ok is not None for r in replies):
            break
        time.sleep(0.1)
    print("kpl subscribed", flush=True)

    publisher = session.declare_publisher(topic_keyexpr(0, "/tracker/markers", dds, markers_hash))
    pub_token = session.liveliness().declare_token(endpoint_liveliness_keyexpr(pub_entity))
    gid = os.urandom(16)
    seq = 0
    recording = list(frames(args.fcd, args.start, args.seconds))
    ids = {}
    began = time.time()
    first = recording[0][0]
    for t, vehicles in recording:
        delay = began + (t - first) - time.time()
        if delay > 0:
            time.sleep(delay)
        now = time.time_ns()
        msg = MarkerArray()
        for vehicle, x, y in vehicles:
            m = Marker()
            m.header.stamp = stamp(now)
            m.header.frame_id = "map"
            m.ns = "tracker"
            m.id = ids.setdefault(vehicle, len(ids) + 1)
            m.type = Marker.CUBE
            m.pose.position = Point(x=x, y=y, z=0.0)
            m.pose.orientation.w = 1.0
            m.scale.x, m.scale.y, m.scale.z = VEHICLE_LENGTH, 1.8, 1.5
            msg.markers.append(m)
        seq += 1
        publisher.put(serialize_message(msg), attachment=Attachment(sequence_id=seq, timestamp_ns=now, gid=gid).to_bytes())
        result["published_frames"] += 1
        result["published_markers"] += len(vehicles)
    # Three bad messages, each to be counted by kpl: no attachment, a wrong type hash, cut CDR.
    good = serialize_message(MarkerArray())
    seq += 1
    publisher.put(good)
    # A publisher of the topic with another definition of the type: a node declares it in the
    # graph (its token carries the hash), and kpl, which subscribes to its own type's key as
    # rmw_zenoh does, subscribes to this one's to count its messages.
    wrong_hash = "RIHS01_" + "0" * 64
    wrong_entity = EndpointEntity(node=node, entity_id=3, kind=EntityKind.PUBLISHER, name="/tracker/markers",
                                  dds_type_name=dds, type_hash=wrong_hash, qos=qos)
    wrong_token = session.liveliness().declare_token(endpoint_liveliness_keyexpr(wrong_entity))
    wrong = session.declare_publisher(topic_keyexpr(0, "/tracker/markers", dds, wrong_hash))
    deadline = time.time() + 10
    while not wrong.matching_status.matching and time.time() < deadline:
        time.sleep(0.05)
    wrong.put(good, attachment=Attachment(sequence_id=seq, timestamp_ns=time.time_ns(), gid=gid).to_bytes())
    seq += 1
    publisher.put(serialize_message(msg)[:7], attachment=Attachment(sequence_id=seq, timestamp_ns=time.time_ns(), gid=gid).to_bytes())
    time.sleep(0.5)
    graph = [str(r.ok.key_expr) for r in session.liveliness().get("@ros2_lv/0/**", timeout=2.0) if r.ok is not None]
    result["graph"] = sorted(g for g in graph if "/tracker" not in g.split("/")[8:9] and g.split("/")[2] != zid)
    wrong.undeclare()
    wrong_token.undeclare()
    pub_token.undeclare()
    publisher.undeclare()
    # kpl ends a few seconds after the publisher has gone: wait for its node to leave the graph.
    deadline = time.time() + 30
    while time.time() < deadline:
        replies = [r for r in session.liveliness().get("@ros2_lv/0/**/NN/**", timeout=1.0) if r.ok is not None]
        if not any(str(r.ok.key_expr).split("/")[2] != zid for r in replies):
            break
        time.sleep(0.2)
    cars_sub.undeclare()
    det_sub.undeclare()
    sub_token.undeclare()
    node_token.undeclare()
    session.close()
    Path(args.out).write_text(json.dumps(result))


if __name__ == "__main__":
    main()
