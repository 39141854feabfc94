"""Watches streams between the hosts of a KPL deployment: prints each sample as a JSON line with
the host that sent it and its sequence number, until every stream has ended, then what was
refused (no envelope, another host, a tag that does not verify with the deployment's keys, a
replay) and lost; it gives up after `--idle` seconds without any message (exit status 1). With
`--keys`, it links over mutual TLS with the certificate of host `--as`
and accepts only messages tagged with the deployment's secret.

    python python/examples/watch.py --connect tcp/127.0.0.1:7447 --spec python readings too_hot
    python python/examples/watch.py --connect tls/127.0.0.1:7447 --keys KEYS --as station \\
        --spec python readings too_hot
"""

import argparse
import json
import sys
import time

import kpl


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("producers", nargs="+", help="processes whose output to watch (PRODUCER or PRODUCER/PORT)")
    parser.add_argument("--spec", required=True, help="the spec's file stem")
    parser.add_argument("--deployment", default=kpl.DEFAULT_DEPLOYMENT, help="the deployment's name")
    parser.add_argument("--from-host", help="the host the spec places the producers on (refuse others)")
    parser.add_argument("--connect", default="tcp/127.0.0.1:7447", help="endpoint of the producing host")
    parser.add_argument("--keys", help="the deployment's keys folder (kpl keys)")
    parser.add_argument("--as", dest="host", help="with --keys: the host whose certificate to link with")
    parser.add_argument("--idle", type=float, default=60.0, help="give up after this many seconds without a message")
    parser.add_argument("--wait", type=float, default=60.0, help="seconds to wait for the host")
    args = parser.parse_args()

    with kpl.Session([args.connect], keys=args.keys, host=args.host, wait=args.wait) as session:
        streams = {}
        for name in args.producers:
            producer, _, port = name.partition("/")
            streams[name] = session.stream(
                args.spec, producer, port or None, deployment=args.deployment, host=args.from_host
            )
        print(json.dumps({"watching": [s.key for s in streams.values()]}), flush=True)
        open_ = dict(streams)
        idle = time.monotonic()
        seen = 0
        while open_ and time.monotonic() - idle < args.idle:
            for name, stream in list(open_.items()):
                message = stream.recv(timeout=0.05)
                if isinstance(message, kpl.Ended):
                    del open_[name]
                    print(json.dumps({"stream": name, "end": message.published}), flush=True)
                elif message is not None:
                    e = message.envelope
                    line = {"stream": name, "host": e.host, "sequence": e.sequence, "authenticated": e.authenticated}
                    line.update(valid=message.valid, available=message.available, value=message.value)
                    print(json.dumps(line), flush=True)
            arrived = sum(s.messages for s in streams.values())
            if arrived != seen:
                seen, idle = arrived, time.monotonic()
        for name, stream in streams.items():
            report = {"refused": stream.refused, "lost": stream.lost, "malformed": stream.malformed}
            print(json.dumps({"stream": name, **report, "reasons": stream.reasons}), flush=True)
    if open_:
        print(f"no end after {args.idle} s without a message: {sorted(open_)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
