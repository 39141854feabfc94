"""A program outside a KPL spec, talking to `kpl run` over zenoh (run by tests/zenoh.rs).

It knows KPL's wire format only from docs/streams.md: it takes the Python block of the section
"On the wire" from that file and runs it, so the documented code is the code under test.

    python zenoh_client.py DOCS ENDPOINT IN_KEY OUT_KEY SAMPLES

- connects to the kpl run at ENDPOINT (a zenoh client; the run listens);
- subscribes to OUT_KEY, where the run publishes;
- publishes on IN_KEY, once the run subscribed: one malformed message, then the samples of the
  JSON-lines file SAMPLES (`{"valid": ..., "available": ..., "value": ...}`), then the end;
- prints every sample that arrives on OUT_KEY, decoded, as a JSON line, until the end message.
"""

import json
import re
import sys
import time

import zenoh

WAIT = 60.0


def documented_codec(docs_path):
    text = open(docs_path, encoding="utf-8").read()
    section = text.split("## On the wire", 1)[1]
    blocks = re.findall(r"```python\n(.*?)```", section, re.S)
    codec = [b for b in blocks if "def decode" in b]
    if not codec:
        sys.exit("docs/streams.md has no Python block with `def decode` under `## On the wire`")
    namespace = {}
    exec(codec[0], namespace)
    return namespace["decode"], namespace["encode_sample"], namespace["encode_end"]


def until(what, condition):
    deadline = time.monotonic() + WAIT
    while not condition():
        if time.monotonic() > deadline:
            sys.exit(f"gave up waiting for {what}")
        time.sleep(0.01)


def main():
    docs, endpoint, in_key, out_key, samples_path = sys.argv[1:6]
    decode, encode_sample, encode_end = documented_codec(docs)
    samples = [json.loads(line) for line in open(samples_path, encoding="utf-8") if line.strip()]

    config = zenoh.Config()
    config.insert_json5("mode", '"client"')
    config.insert_json5("connect/endpoints", json.dumps([endpoint]))
    session = None
    deadline = time.monotonic() + WAIT
    while session is None:
        try:
            session = zenoh.open(config)
        except zenoh.ZError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.05)

    subscriber = session.declare_subscriber(out_key)
    publisher = session.declare_publisher(in_key)
    until("kpl to subscribe", lambda: publisher.matching_status.matching)

    publisher.put(b"not a KPL message")
    for s in samples:
        publisher.put(encode_sample(s["valid"], s["available"], s["value"]))
    publisher.put(encode_end(len(samples)))

    deadline = time.monotonic() + WAIT
    while True:
        sample = subscriber.try_recv()
        if sample is None:
            if time.monotonic() > deadline:
                sys.exit("gave up waiting for the end of the forwarded stream")
            time.sleep(0.001)
            continue
        message = decode(sample.payload.to_bytes())
        if message[0] == "end":
            print(json.dumps({"end": message[1]}), flush=True)
            break
        _, valid, available, value = message
        print(json.dumps({"valid": valid, "available": available, "value": value}), flush=True)
    session.close()


if __name__ == "__main__":
    main()
