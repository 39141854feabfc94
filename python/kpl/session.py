"""A zenoh session that talks to a running KPL deployment: publishers and subscriptions that speak
KPL's wire format (:mod:`kpl.wire`), its keys (:mod:`kpl.keys`) and, for the streams between its
hosts, its envelopes (:mod:`kpl.envelope`).
"""

from __future__ import annotations

import atexit
import bisect
import json
import os
import queue
import threading
import time
import weakref
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator, Sequence

import zenoh

from . import envelope as env
from . import keys as kpl_keys
from . import wire

#: How many reasons for malformed or refused messages a subscription keeps.
KEEP_REASONS = 10

#: Sessions still open: closed when the interpreter exits, so that no thread is left blocked in
#: zenoh while Python shuts down.
_OPEN: "weakref.WeakSet[Session]" = weakref.WeakSet()


@atexit.register
def _close_open_sessions() -> None:
    for session in list(_OPEN):
        session.close()


def now() -> int:
    """The wall clock in microseconds since the UNIX epoch: the time of ``kpl run --clock wall``."""
    return time.time_ns() // 1000


@dataclass(frozen=True)
class Received:
    """A sample that arrived: the key it came on, its times (microseconds), its value and, on a
    stream between hosts, its envelope."""

    key: str
    valid: int
    available: int
    value: Any
    envelope: "env.Envelope | None" = None


@dataclass(frozen=True)
class Ended:
    """The end of the stream on ``key``: its producer published ``published`` samples."""

    key: str
    published: int
    envelope: "env.Envelope | None" = None


class Session:
    """A zenoh session linked to the hosts of a deployment.

    ``connect``: endpoints of KPL hosts to dial (``tcp/127.0.0.1:7447``: the first host of a spec
    with the loopback defaults); ``listen``: endpoints to listen on instead or as well. ``mode``:
    ``"client"`` (the default: the program reaches the deployment through the hosts it dials) or
    ``"peer"``. ``keys``: the deployment's keys folder (``kpl keys``), to link over ``tls/`` with
    the certificate of ``host`` (a host of the spec's deploy section) and to verify the envelopes'
    tags with the deployment's secret. ``config``: more zenoh settings, ``{"path/in/config":
    value}``. ``wait``: seconds to keep dialling while no host listens yet.
    """

    def __init__(
        self,
        connect: Sequence[str] = ("tcp/127.0.0.1:7447",),
        *,
        listen: Sequence[str] = (),
        mode: str = "client",
        keys: "str | os.PathLike[str] | None" = None,
        host: "str | None" = None,
        config: "dict[str, Any] | None" = None,
        wait: float = 30.0,
    ):
        if isinstance(connect, str):
            connect = [connect]
        if isinstance(listen, str):
            listen = [listen]
        settings: dict[str, Any] = {
            "mode": mode,
            "scouting/multicast/enabled": False,
            "connect/endpoints": list(connect),
            "listen/endpoints": list(listen),
        }
        self.secret: "bytes | None" = None
        if keys is not None:
            folder = Path(keys)
            self.secret = env.read_secret(folder)
            if host is not None:
                settings.update(tls_settings(folder, host))
        settings.update(config or {})
        zconfig = zenoh.Config()
        for path, value in settings.items():
            zconfig.insert_json5(path, json.dumps(value))
        self._subscriptions: "weakref.WeakSet[Subscription]" = weakref.WeakSet()
        self._closed = False
        deadline = time.monotonic() + wait
        while True:
            try:
                self.zenoh = zenoh.open(zconfig)
                _OPEN.add(self)
                break
            except zenoh.ZError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.05)

    def publisher(self, key: str) -> "Publisher":
        """A publisher of samples on ``key`` (no wildcards), for ``zenoh.subscribe(key: ...)`` in a
        spec."""
        return Publisher(self, key)

    def subscribe(self, key: str, *, stop_at_end: bool = True, queue_size: int = 4096) -> "Subscription":
        """Samples published on ``key`` (wildcards allowed): by ``zenoh.publish(..., key: ...)`` in
        a spec, or by another :class:`Publisher`. Iterating ends at the first end message when
        ``stop_at_end``."""
        return Subscription(self, key, envelopes=False, stop_at_end=stop_at_end, queue_size=queue_size)

    def stream(
        self,
        spec: str,
        producer: str,
        port: "str | None" = None,
        *,
        deployment: str = kpl_keys.DEFAULT_DEPLOYMENT,
        host: "str | None" = None,
        stop_at_end: bool = True,
        queue_size: int = 4096,
    ) -> "Subscription":
        """A stream sent between the hosts of a deployment: the output of ``producer`` (its named
        output ``port``) of the spec whose file stem is ``spec``. Its messages must carry an
        envelope (from ``host``, if given), tagged with the deployment's secret when the session
        has keys, in sequence; the others are refused and counted, as a host of the deployment
        refuses them."""
        key = kpl_keys.stream(spec, producer, port, deployment)
        return Subscription(
            self, key, envelopes=True, host=host, stop_at_end=stop_at_end, queue_size=queue_size
        )

    def close(self) -> None:
        """Ends the subscriptions and closes the zenoh session (again: nothing)."""
        if self._closed:
            return
        self._closed = True
        for subscription in list(self._subscriptions):
            subscription.close()
        self.zenoh.close()
        _OPEN.discard(self)

    def __enter__(self) -> "Session":
        return self

    def __exit__(self, *_exc: Any) -> None:
        self.close()


def tls_settings(keys: Path, host: str) -> "dict[str, Any]":
    """The zenoh settings of mutual TLS with a host's certificate from a keys folder, as KPL's
    hosts set them (the peer is known by its certificate's common name, not its address)."""
    files = {"ca": keys / "ca.pem", "certificate": keys / f"{host}.pem", "key": keys / f"{host}.key"}
    for what, path in files.items():
        if not path.is_file():
            raise FileNotFoundError(f"{path}: the {what} of host `{host}` is not in the keys folder")
    return {
        "transport/link/tls/root_ca_certificate": str(files["ca"]),
        "transport/link/tls/listen_certificate": str(files["certificate"]),
        "transport/link/tls/listen_private_key": str(files["key"]),
        "transport/link/tls/connect_certificate": str(files["certificate"]),
        "transport/link/tls/connect_private_key": str(files["key"]),
        "transport/link/tls/enable_mtls": True,
        "transport/link/tls/verify_name_on_connect": False,
    }


class Publisher:
    """Publishes samples on one key and ends the stream with an end message (the count of samples
    published), as ``zenoh.publish`` does. Blocks rather than drops when the network is slow."""

    def __init__(self, session: Session, key: str):
        self.key = key
        self.published = 0
        self._publisher = session.zenoh.declare_publisher(
            key, congestion_control=zenoh.CongestionControl.BLOCK
        )

    def wait_for_subscriber(self, timeout: float = 30.0) -> bool:
        """Waits until a subscriber matches the key (a KPL host whose ``zenoh.subscribe`` started);
        whether one did within ``timeout`` seconds."""
        deadline = time.monotonic() + timeout
        while not self._publisher.matching_status.matching:
            if time.monotonic() > deadline:
                return False
            time.sleep(0.01)
        return True

    def put(self, value: Any, valid: "int | None" = None, available: "int | None" = None) -> None:
        """Publishes one sample. ``valid`` defaults to :func:`now`, ``available`` to ``valid``
        (integer microseconds; ``kpl run --clock wall`` keeps times since the UNIX epoch, and a
        ``zenoh.subscribe`` source keeps the times a sample was sent with)."""
        valid = now() if valid is None else valid
        available = valid if available is None else available
        self._publisher.put(wire.encode_sample(valid, available, value))
        self.published += 1

    def end(self) -> None:
        """Ends the stream: a ``zenoh.subscribe`` source (with ``stop_at_end``) ends."""
        self._publisher.put(wire.encode_end(self.published))

    def close(self) -> None:
        self._publisher.undeclare()

    def __enter__(self) -> "Publisher":
        return self

    def __exit__(self, *_exc: Any) -> None:
        self.close()


class Subscription:
    """Samples of one key expression, decoded, in the order they arrive. Messages that do not
    decode are counted (``malformed``), and on streams between hosts so are those whose envelope
    is refused (``refused``) and the gaps in the sequence numbers (``lost``); the first reasons are
    kept in ``reasons``. Iterating yields :class:`Received` samples and stops at the end of the
    stream (``ended`` then holds it) when ``stop_at_end``. On a key expression with wildcards, each
    key's stream ends by itself: use :meth:`recv` and count the :class:`Ended`."""

    def __init__(
        self,
        session: Session,
        key: str,
        *,
        envelopes: bool,
        host: "str | None" = None,
        stop_at_end: bool = True,
        queue_size: int = 4096,
    ):
        self.key = key
        #: Every message that arrived, accepted or not.
        self.messages = 0
        self.malformed = 0
        self.refused = 0
        self.lost = 0
        self.restarts = 0
        self.reasons: list[str] = []
        self.ended: "Ended | None" = None
        self._secret = session.secret
        self._envelopes = envelopes
        self._host = host
        self._stop_at_end = stop_at_end
        self._sequences: dict[str, _Sequence] = {}
        # Bounded on both sides: zenoh's channel and the queue the pump thread fills. When both
        # are full zenoh's delivery waits (and, through BLOCK congestion control, the publisher),
        # rather than dropping samples or growing without bound.
        self._queue: "queue.Queue[zenoh.Sample]" = queue.Queue(maxsize=queue_size)
        self._subscriber = session.zenoh.declare_subscriber(key, zenoh.handlers.FifoChannel(queue_size))
        self._pump = threading.Thread(target=self._forward, name=f"kpl {key}", daemon=True)
        self._pump.start()
        self._closed = False
        session._subscriptions.add(self)

    def _forward(self) -> None:
        """Moves samples from zenoh's channel into the queue that :meth:`recv` reads with a
        timeout, until the subscription is undeclared."""
        try:
            for sample in self._subscriber.handler:
                self._queue.put(sample)
        except zenoh.ZError:
            pass

    def _count(self, what: str, reason: str) -> None:
        setattr(self, what, getattr(self, what) + 1)
        if len(self.reasons) < KEEP_REASONS:
            self.reasons.append(reason)

    def recv(self, timeout: "float | None" = None) -> "Received | Ended | None":
        """The next sample or end of the stream; None when none came within ``timeout`` seconds
        (None: wait for ever). Malformed and refused messages are counted and skipped."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            left = None if deadline is None else max(0.0, deadline - time.monotonic())
            try:
                sample = self._queue.get(timeout=left)
            except queue.Empty:
                return None
            message = self._read(sample)
            if message is not None:
                return message

    def _read(self, sample: "zenoh.Sample") -> "Received | Ended | None":
        self.messages += 1
        key = str(sample.key_expr)
        payload = sample.payload.to_bytes()
        try:
            message = wire.decode(payload)
        except wire.WireError as e:
            self._count("malformed", f"{key}: {e}")
            return None
        envelope = None
        if self._envelopes:
            attachment = sample.attachment.to_bytes() if sample.attachment is not None else None
            try:
                envelope = env.open_(attachment, key, payload, self._secret)
            except env.EnvelopeError as e:
                self._count("refused", f"{key}: {e}")
                return None
            if self._host is not None and envelope.host != self._host:
                self._count("refused", f"{key}: from host `{envelope.host}`, not `{self._host}`")
                return None
            sequence = self._sequences.setdefault(key, _Sequence())
            verdict = sequence.accept(envelope, isinstance(message, wire.End))
            if isinstance(verdict, str):
                self._count("refused", f"{key}: {verdict}")
                return None
            _, restarted = verdict
            self.lost = sum(q.lost() for q in self._sequences.values())
            self.restarts += restarted
        if isinstance(message, wire.End):
            if envelope is not None and envelope.unfinished:
                # The producer was interrupted; a restarted one goes on with the stream.
                return None
            return Ended(key, message.published, envelope)
        return Received(key, message.valid, message.available, message.value, envelope)

    def __iter__(self) -> Iterator[Received]:
        while True:
            message = self.recv()
            if isinstance(message, Ended):
                self.ended = message
                if self._stop_at_end:
                    return
            elif message is not None:
                yield message

    def samples(self, count: "int | None" = None, timeout: float = 30.0) -> "list[Received]":
        """Up to ``count`` samples (all of them up to the end of the stream when None), waiting at
        most ``timeout`` seconds for each."""
        out: list[Received] = []
        while count is None or len(out) < count:
            message = self.recv(timeout)
            if message is None:
                raise TimeoutError(f"{self.key}: nothing for {timeout} s after {len(out)} sample(s)")
            if isinstance(message, Ended):
                self.ended = message
                if self._stop_at_end:
                    break
                continue
            out.append(message)
        return out

    def close(self) -> None:
        """Undeclares the subscription (again: nothing); samples already queued can still be read."""
        if self._closed:
            return
        self._closed = True
        try:
            self._subscriber.undeclare()
        except zenoh.ZError:
            pass  # the session is closed already
        self._pump.join(timeout=5.0)

    def __enter__(self) -> "Subscription":
        return self

    def __exit__(self, *_exc: Any) -> None:
        self.close()


class _Sequence:
    """The sequence numbers seen on one stream, as a KPL host checks them: a message whose
    (incarnation, sequence number) was accepted before is a replay or a duplicate; anything else
    is accepted, so that no message (a far sequence number, a new incarnation) can shut the
    producer's own messages out. A new incarnation is a restart."""

    RUNS = 16
    RANGES = 1024

    def __init__(self) -> None:
        # incarnation -> [ranges [start, end) sorted, received, frontier, ended, touched]
        self.runs: dict[int, list] = {}
        self.current: "int | None" = None
        self.forgotten_lost = 0
        self.clock = 0

    def lost(self) -> int:
        return self.forgotten_lost + sum(max(0, r[2] - r[1]) for r in self.runs.values())

    def accept(self, envelope: env.Envelope, is_end: bool) -> "tuple[int, bool] | str":
        """(samples newly counted lost, restarted), or why the message is refused."""
        self.clock += 1
        before = self.lost()
        run = self.runs.get(envelope.incarnation)
        restarted = False
        if run is None:
            if len(self.runs) == self.RUNS:
                oldest = min(self.runs, key=lambda i: self.runs[i][4])
                old = self.runs.pop(oldest)
                self.forgotten_lost += max(0, old[2] - old[1])
            restarted = self.current is not None and self.current != envelope.incarnation
            run = self.runs[envelope.incarnation] = [[], 0, 0, False, self.clock]
        ranges = run[0]
        s = envelope.sequence
        if is_end:
            if run[3]:
                return f"the end again (incarnation {envelope.incarnation:016x}): replayed"
            run[3] = True
            run[2] = max(run[2], s)
        else:
            i = bisect.bisect_right(ranges, [s, float("inf")])
            if i > 0 and ranges[i - 1][0] <= s < ranges[i - 1][1]:
                return f"sequence number {s} again: replayed or duplicated"
            if i > 0 and ranges[i - 1][1] == s:
                ranges[i - 1][1] = s + 1
                if i < len(ranges) and ranges[i][0] == s + 1:
                    ranges[i - 1][1] = ranges[i][1]
                    del ranges[i]
            elif i < len(ranges) and ranges[i][0] == s + 1:
                ranges[i][0] = s
            else:
                ranges.insert(i, [s, s + 1])
                if len(ranges) > self.RANGES:
                    ranges.pop()
            run[1] += 1
            run[2] = max(run[2], s + 1)
        run[4] = self.clock
        self.current = envelope.incarnation
        return max(0, self.lost() - before), restarted
