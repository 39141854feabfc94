"""Compares what a Foxglove WebSocket client received from `kpl run --foxglove` with the run's
JSON-lines recording of its cars (tests/view.rs runs this):

    python tests/foxglove_live.py RECEIVED.jsonl TRACKS.jsonl

RECEIVED.jsonl is what tests/node/foxglove_client.mjs wrote (Foxglove's own protocol client).
Each message of `/kpl/onroad_car` is parsed with Foxglove's `foxglove-schemas-protobuf`: a scene
update whose entities are the cars of one sample of `onroad_car`, with the same symbols, the
sample's valid time as the entities' timestamp and its available time as the message's log time.
Every recorded sample must have been received once. Prints a JSON report.
"""

import base64
import json
import sys

import foxglove_schemas_protobuf.SceneUpdate_pb2 as SceneUpdate


def main(received_path, tracks_path):
    recorded = {}
    for line in open(tracks_path, encoding="utf-8"):
        r = json.loads(line)
        if r["stream"] == "onroad_car":
            recorded[r["valid"]] = (r["available"], sorted(o["id"] for o in r["value"]))
    got = {}
    problems = []
    end = None
    for line in open(received_path, encoding="utf-8"):
        m = json.loads(line)
        if "end" in m:
            end = m
            continue
        if m["topic"] != "/kpl/onroad_car":
            continue
        if m["schema"] != "foxglove.SceneUpdate" or m["encoding"] != "protobuf":
            problems.append(f"schema {m['schema']} / {m['encoding']}")
            continue
        update = SceneUpdate.SceneUpdate.FromString(base64.b64decode(m["data"]))
        # The update replaces what was there before its time (a deletion of everything, stamped
        # with the sample's valid time), then adds the entities, stamped the same.
        us = lambda t: t.seconds * 1_000_000 + t.nanos // 1000
        stamps = {us(d.timestamp) for d in update.deletions} | {us(e.timestamp) for e in update.entities}
        log_us = int(m["log_time"]) // 1000
        if len(stamps) != 1:
            problems.append(f"a message whose entities have times {stamps} at log time {log_us}")
            continue
        valid = stamps.pop()
        if valid in got:
            problems.append(f"two messages for {valid}")
        got[valid] = (log_us, sorted(e.id for e in update.entities))
    missing = [v for v in recorded if v not in got]
    extra = [v for v in got if v not in recorded]
    for valid in sorted(set(got) & set(recorded)):
        if got[valid] != recorded[valid]:
            problems.append(f"at {valid}: received {got[valid]}, recorded {recorded[valid]}")
    caps = (end or {}).get("server") or {}
    report = {
        "samples": len(recorded),
        "received": len(got),
        "cars": sum(len(s) for _, s in got.values()),
        "missing": len(missing),
        "first_missing": sorted(missing)[:5],
        "extra": len(extra),
        "problems": problems[:10],
        "time_capability": "time" in caps.get("capabilities", []),
        "channels": sorted(c["topic"] for c in (end or {}).get("channels", [])),
        "end": (end or {}).get("end"),
    }
    print(json.dumps(report, sort_keys=True))
    if problems:
        sys.exit(1)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
