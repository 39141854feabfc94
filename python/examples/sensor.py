"""A Python source of a KPL deployment: a greenhouse sensor publishing readings (a position, a
temperature and a spectrum of floats) into the spec's `zenoh.subscribe(key: "kpl-demo/readings")`
(specs/zenoh/python.kpl), then the end of the stream. Prints each sample it sent as a JSON line.

    python python/examples/sensor.py --connect tcp/127.0.0.1:7447 --count 50 --period 0.02
"""

import argparse
import json
import math
import random
import sys
import time

import kpl


def reading(i: int, count: int, rng: random.Random) -> dict:
    """The i-th of `count` readings: warming from 20 to about 35 degrees, a wobbling position, 16
    bands."""
    return {
        "id": f"rd{i}",
        "pos": kpl.Vec2(2.0 + math.cos(i / 5.0), 3.0 + math.sin(i / 5.0)),
        "temp": 20.0 + 15.0 * i / max(count - 1, 1) + rng.gauss(0.0, 0.3),
        "spectrum": [rng.random() for _ in range(16)],
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--connect", default="tcp/127.0.0.1:7447", help="endpoint of the host that subscribes")
    parser.add_argument("--key", default="kpl-demo/readings")
    parser.add_argument("--count", type=int, default=50, help="readings to publish")
    parser.add_argument("--period", type=float, default=0.02, help="seconds between readings")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--wait", type=float, default=60.0, help="seconds to wait for the host")
    parser.add_argument("--keys", help="the deployment's keys folder (kpl keys), to link over mutual TLS")
    parser.add_argument("--as", dest="host", help="with --keys: the host whose certificate to link with")
    args = parser.parse_args()

    rng = random.Random(args.seed)
    with kpl.Session([args.connect], keys=args.keys, host=args.host, wait=args.wait) as session:
        readings = session.publisher(args.key)
        if not readings.wait_for_subscriber(args.wait):
            print(f"no subscriber on {args.key} after {args.wait} s", file=sys.stderr)
            return 1
        for i in range(args.count):
            value = reading(i, args.count, rng)
            valid = kpl.now()
            readings.put(value, valid=valid, available=valid)
            print(json.dumps({"valid": valid, "available": valid, "value": value}), flush=True)
            time.sleep(args.period)
        readings.end()
        # Give zenoh a moment to deliver the end before the session closes.
        time.sleep(0.5)
    return 0


if __name__ == "__main__":
    sys.exit(main())
