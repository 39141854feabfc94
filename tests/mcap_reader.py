"""Reads a KPL MCAP recording with the `mcap` Python package, as any robotics user would, and
checks it against the JSON-lines recording of the same run (tests/mcap.rs runs this).

    python tests/mcap_reader.py RECORDING.mcap RECORDING.jsonl

For every stream: the channel's topic is the stream's name, its messages are JSON described by
the channel's JSON schema (each message is validated against it), the messages have the samples
of the JSON lines in the same order, with the same valid and available times (also as MCAP's
publish and log times, in nanoseconds) and the same values. Channels written for viewers
(metadata `kpl.view`: Foxglove's schemas, checked by tests/foxglove_mcap.py) are left out. Prints
a JSON report (streams with their counts, schema names and time ranges) on standard output; exits
1 on the first difference.

    python tests/mcap_reader.py --cut RECORDING.mcap

reads a file that a killed run left (no summary, no footer) linearly, as far as it goes: prints
each message of the streams' channels as a JSON line (`stream`, `valid`, `available`, `value`)
and, last, `{"end": ...}` with how the reading ended.
"""

import json
import sys
from collections import defaultdict

import jsonschema
from mcap.exceptions import McapError
from mcap.reader import NonSeekingReader, make_reader


def fail(message):
    print(message, file=sys.stderr)
    sys.exit(1)


def main(mcap_path, jsonl_path):
    expected = defaultdict(list)
    with open(jsonl_path, encoding="utf-8") as f:
        for line in f:
            if line.strip():
                r = json.loads(line)
                expected[r["stream"]].append((r["valid"], r["available"], r["value"]))

    got = defaultdict(list)
    report = {"streams": {}}
    validators = {}
    with open(mcap_path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        header = reader.get_header()
        report["library"] = header.library
        summary = reader.get_summary()
        for channel in summary.channels.values():
            if "kpl.view" in channel.metadata:
                continue
            schema = summary.schemas[channel.schema_id]
            if channel.message_encoding != "json" or schema.encoding != "jsonschema":
                fail(f"{channel.topic}: {channel.message_encoding} / {schema.encoding}")
            validators[channel.id] = jsonschema.Draft202012Validator(json.loads(schema.data))
            report["streams"][channel.topic] = {
                "schema": schema.name,
                "type": channel.metadata.get("kpl.type"),
                "count": summary.statistics.channel_message_counts.get(channel.id, 0),
            }
        sequences = defaultdict(int)
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            if "kpl.view" in channel.metadata:
                continue
            body = json.loads(message.data)
            errors = list(validators[channel.id].iter_errors(body))
            if errors:
                fail(f"{channel.topic}: message {message.sequence} does not fit its schema: {errors[0].message}")
            sequences[channel.id] += 1
            if message.sequence != sequences[channel.id]:
                fail(f"{channel.topic}: sequence {message.sequence}, expected {sequences[channel.id]}")
            if message.log_time != body["available"] * 1000 or message.publish_time != body["valid"] * 1000:
                fail(f"{channel.topic}: MCAP times {message.publish_time}/{message.log_time} for {body}")
            got[channel.topic].append((body["valid"], body["available"], body["value"]))

    if sorted(got) != sorted(expected):
        fail(f"streams {sorted(got)} in the MCAP, {sorted(expected)} in the JSON lines")
    for stream, samples in expected.items():
        if got[stream] != samples:
            n = next((i for i, (a, b) in enumerate(zip(got[stream], samples)) if a != b), None)
            fail(f"{stream}: {len(got[stream])} messages, {len(samples)} lines; first difference at {n}")
        report["streams"][stream]["valid"] = [samples[0][0], samples[-1][0]] if samples else []
    print(json.dumps(report, sort_keys=True))


def cut(mcap_path):
    end = "the end of the file"
    with open(mcap_path, "rb") as f:
        reader = NonSeekingReader(f, validate_crcs=True)
        try:
            for schema, channel, message in reader.iter_messages(log_time_order=False):
                if "kpl.view" in channel.metadata:
                    continue
                body = json.loads(message.data)
                print(json.dumps({"stream": channel.topic, **body}, sort_keys=True))
        except (McapError, EOFError) as e:
            end = f"{type(e).__name__}: {e}"
    print(json.dumps({"end": end}))


if __name__ == "__main__":
    if sys.argv[1] == "--cut":
        cut(sys.argv[2])
    else:
        main(sys.argv[1], sys.argv[2])
