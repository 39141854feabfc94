"""An outside zenoh peer that tries to slip samples and an end into a deployment's stream
(run by tests/zenoh.rs). It knows KPL's formats only from docs/streams.md: it runs the Python
blocks of the section "On the wire" (the message codec and the envelope).

    python zenoh_forger.py DOCS check
        prints, as JSON, envelopes sealed by the documented code for fixed inputs, and opens the
        ones given on standard input (one JSON object per line), so the test can compare both
        with kpl's own;
    python zenoh_forger.py DOCS forge MODE ENDPOINT KEY COUNT [KEYS HOST]
        connects to ENDPOINT as a zenoh client and publishes COUNT forged samples and a forged end
        on KEY, then prints one JSON line saying what happened:
        - MODE `plain`: no envelope on half of them, an envelope naming the producer without a tag
          on the others (a stranger without the deployment's keys);
        - MODE `member`: with the certificate of HOST from the keys folder KEYS and valid tags made
          with its secret, naming the producer (a host of the deployment impersonating another);
        - MODE `nocert`: over TLS trusting the deployment's authority but without a certificate;
        - MODE `wrongkey`: envelopes naming the producer, tagged with a secret of its own (a
          stranger guessing at the deployment's keys), with a far sequence number first (to shut
          the producer out, if kpl let it);
    python zenoh_forger.py DOCS tokens ENDPOINT SECONDS TOKEN...
        connects to ENDPOINT as a zenoh client, declares each liveliness TOKEN (a key expression:
        a subscriber's, a host's, a done token) and holds them SECONDS, then prints one JSON line.
"""

import json
import os
import re
import sys
import time

WAIT = 30.0
#: The producing host forged envelopes name (the environment's KPL_FORGE_AS, else `uav`).
AS_HOST = os.environ.get("KPL_FORGE_AS", "uav")


def documented(docs_path):
    text = open(docs_path, encoding="utf-8").read()
    section = text.split("## On the wire", 1)[1]
    namespace = {}
    for block in re.findall(r"```python\n(.*?)```", section, re.S):
        if "def decode" in block or "def seal_envelope" in block:
            exec(block, namespace)
    for name in ("encode_sample", "encode_end", "seal_envelope", "open_envelope"):
        if name not in namespace:
            sys.exit(f"docs/streams.md has no `{name}` in a Python block under `## On the wire`")
    return namespace


def check(ns):
    secret = bytes(range(32))
    cases = [
        ("kpl/d/s/p", b"payload", "uav", 0xFEED, 41, None, False),
        ("kpl/d/s/p", b"payload", "uav", 0xFEED, 41, secret, False),
        ("kpl/trial/my%20spec/link/changes", b"", "gr\u00f6und", 2**64 - 1, 7, secret, True),
    ]
    for key, payload, host, incarnation, sequence, key_bytes, unfinished in cases:
        sealed = ns["seal_envelope"](key, payload, host, incarnation, sequence, key_bytes, unfinished)
        print(json.dumps({"sealed": sealed.hex()}))
    for line in sys.stdin:
        case = json.loads(line)
        key_bytes = bytes.fromhex(case["secret"]) if case["secret"] else None
        try:
            opened = ns["open_envelope"](
                bytes.fromhex(case["attachment"]), case["key"], bytes.fromhex(case["payload"]), key_bytes
            )
            print(json.dumps({"opened": list(opened)}))
        except ValueError as e:
            print(json.dumps({"refused": str(e)}))


def forge(ns, mode, endpoint, key, count, keys=None, host=None):
    import zenoh

    config = zenoh.Config()
    config.insert_json5("mode", '"client"')
    config.insert_json5("connect/endpoints", json.dumps([endpoint]))
    if mode in ("member", "nocert"):
        tls = {"root_ca_certificate": f"{keys}/ca.pem", "verify_name_on_connect": False}
        if mode == "member":
            tls.update(
                enable_mtls=True,
                connect_certificate=f"{keys}/{host}.pem",
                connect_private_key=f"{keys}/{host}.key",
            )
        for name, value in tls.items():
            config.insert_json5(f"transport/link/tls/{name}", json.dumps(value))
    try:
        session = zenoh.open(config)
    except zenoh.ZError as e:
        print(json.dumps({"connected": False, "error": str(e)}), flush=True)
        return
    secret = bytes.fromhex(open(f"{keys}/secret").read().strip()) if mode == "member" else None
    if mode == "wrongkey":
        secret = bytes(range(32))
    publisher = session.declare_publisher(key)
    deadline = time.monotonic() + WAIT
    while not publisher.matching_status.matching:
        if time.monotonic() > deadline:
            break
        time.sleep(0.01)
    matched = publisher.matching_status.matching
    incarnation = 0x0BAD
    sent = 0
    if mode == "wrongkey":
        far = ns["encode_sample"](1_700_000_000_000_000, 1_700_000_000_000_000, -1)
        publisher.put(far, attachment=ns["seal_envelope"](key, far, AS_HOST, incarnation, 2**63, secret))
        sent += 1
    for i in range(count):
        payload = ns["encode_sample"](1_700_000_000_000_000 + i, 1_700_000_000_000_000 + i, -1 - i)
        if mode == "plain" and i % 2 == 0:
            publisher.put(payload)
        else:
            attachment = ns["seal_envelope"](key, payload, AS_HOST, incarnation, i, secret)
            publisher.put(payload, attachment=attachment)
        sent += 1
    end = ns["encode_end"](count)
    publisher.put(end, attachment=ns["seal_envelope"](key, end, AS_HOST, incarnation, count, secret))
    sent += 1
    time.sleep(1.0)
    print(json.dumps({"connected": True, "matched": matched, "sent": sent}), flush=True)
    session.close()


def tokens(endpoint, seconds, keys):
    import zenoh

    config = zenoh.Config()
    config.insert_json5("mode", '"client"')
    config.insert_json5("connect/endpoints", json.dumps([endpoint]))
    session = zenoh.open(config)
    held = [session.liveliness().declare_token(key) for key in keys]
    time.sleep(seconds)
    print(json.dumps({"connected": True, "tokens": len(held)}), flush=True)
    session.close()


def main():
    docs, command = sys.argv[1:3]
    ns = documented(docs)
    if command == "check":
        check(ns)
    elif command == "tokens":
        tokens(sys.argv[3], float(sys.argv[4]), sys.argv[5:])
    else:
        mode, endpoint, key, count = sys.argv[3:7]
        keys, host = (sys.argv[7:9] + [None, None])[:2]
        forge(ns, mode, endpoint, key, int(count), keys, host)


if __name__ == "__main__":
    main()
