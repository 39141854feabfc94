"""A Python sink of a KPL deployment: subscribes to what the spec publishes for programs outside it
(`zenoh.publish(..., key: "kpl-demo/out/...")` in specs/zenoh/python.kpl) and prints every sample
as a JSON line with the key it came on, until `--streams` streams have ended.

    python python/examples/dashboard.py --connect tcp/127.0.0.1:7448 --streams 2
"""

import argparse
import json
import sys

import kpl


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--key", default="kpl-demo/out/*", help="key expression to subscribe to")
    parser.add_argument("--streams", type=int, default=2, help="stop when this many streams have ended")
    parser.add_argument("--connect", default="tcp/127.0.0.1:7448", help="endpoint of the host that publishes")
    parser.add_argument("--timeout", type=float, default=120.0, help="seconds to wait for the next sample")
    parser.add_argument("--wait", type=float, default=60.0, help="seconds to wait for the host")
    parser.add_argument("--keys", help="the deployment's keys folder (kpl keys), to link over mutual TLS")
    parser.add_argument("--as", dest="host", help="with --keys: the host whose certificate to link with")
    args = parser.parse_args()

    with kpl.Session([args.connect], keys=args.keys, host=args.host, wait=args.wait) as session:
        subscription = session.subscribe(args.key)
        print(json.dumps({"subscribed": args.key}), flush=True)
        ended = 0
        while ended < args.streams:
            message = subscription.recv(timeout=args.timeout)
            if message is None:
                print(f"nothing on {args.key} for {args.timeout} s", file=sys.stderr)
                return 1
            if isinstance(message, kpl.Ended):
                ended += 1
                print(json.dumps({"key": message.key, "end": message.published}), flush=True)
            else:
                line = {"key": message.key, "valid": message.valid, "available": message.available}
                print(json.dumps({**line, "value": message.value}), flush=True)
        if subscription.malformed:
            print(f"{subscription.malformed} malformed: {subscription.reasons}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
