"""KPL from Python: publish into and subscribe to the streams of a running KPL deployment over
zenoh, in KPL's wire format (docs/streams.md, "On the wire"; docs/python.md).

    import kpl

    with kpl.Session(["tcp/127.0.0.1:7447"]) as session:
        readings = session.publisher("kpl-demo/readings")      # a spec's zenoh.subscribe(key: ...)
        readings.wait_for_subscriber()
        readings.put({"id": "rd1", "pos": kpl.Vec2(1.0, 2.0), "temp": 21.5})
        readings.end()
        for sample in session.subscribe("kpl-demo/alerts"):   # a spec's zenoh.publish(..., key: ...)
            print(sample.valid, sample.value)
"""

from .envelope import Envelope, EnvelopeError, read_secret
from .keys import DEFAULT_DEPLOYMENT
from .keys import stream as stream_key
from .keys import streams as streams_key
from .session import Ended, Publisher, Received, Session, Subscription, now
from .wire import Box, Duration, End, Sample, Vec2, WireError, decode, encode_end, encode_sample

__version__ = "0.1.0"

__all__ = [
    "DEFAULT_DEPLOYMENT",
    "Box",
    "Duration",
    "End",
    "Ended",
    "Envelope",
    "EnvelopeError",
    "Publisher",
    "Received",
    "Sample",
    "Session",
    "Subscription",
    "Vec2",
    "WireError",
    "decode",
    "encode_end",
    "encode_sample",
    "now",
    "read_secret",
    "stream_key",
    "streams_key",
]
