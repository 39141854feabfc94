"""The envelope of the messages between the hosts of a deployment (docs/streams.md, "Envelope").

Every message a host sends on a stream to another host carries, as its zenoh attachment, which
host sent it, which run of that host (the incarnation), its place in the stream (the sequence
number) and, in a deployment with keys, an HMAC-SHA256 tag made with the deployment's secret.
Messages of ``zenoh.publish`` and to ``zenoh.subscribe`` carry none.
"""

from __future__ import annotations

import hashlib
import hmac
import os
import struct
from dataclasses import dataclass
from pathlib import Path

_HEAD = struct.Struct("<BQQB")
_DOMAIN = b"kpl-envelope-1"
_UNFINISHED = 1
_TAGGED = 2


class EnvelopeError(ValueError):
    """An attachment that is not a KPL envelope, or whose tag does not verify."""


@dataclass(frozen=True)
class Envelope:
    """Who sent a message between hosts, and where it stands in its stream."""

    host: str
    incarnation: int
    sequence: int
    #: On an end: the producer was interrupted (Ctrl-C, SIGTERM) rather than finished.
    unfinished: bool = False
    #: The message carried a tag that verified with the deployment's secret.
    authenticated: bool = False


def read_secret(keys: "str | os.PathLike[str]") -> bytes:
    """The deployment's secret from a keys folder made by ``kpl keys`` (its file ``secret``: 32
    bytes in hex)."""
    path = Path(keys) / "secret"
    text = path.read_text(encoding="ascii").strip()
    try:
        secret = bytes.fromhex(text)
    except ValueError:
        raise EnvelopeError(f"{path} is not hexadecimal") from None
    if len(secret) != 32:
        raise EnvelopeError(f"{path} holds {len(secret)} bytes, not 32")
    return secret


def seal(
    key_expr: str,
    payload: bytes,
    host: str,
    incarnation: int,
    sequence: int,
    secret: "bytes | None" = None,
    unfinished: bool = False,
) -> bytes:
    """The attachment of a message that ``host`` sends on ``key_expr``."""
    name = host.encode("utf-8")
    if len(name) > 255:
        raise EnvelopeError(f"a host name of {len(name)} bytes does not fit an envelope (255 at most)")
    flags = (_UNFINISHED if unfinished else 0) | (_TAGGED if secret is not None else 0)
    envelope = b"KPE\x01" + _HEAD.pack(flags, incarnation, sequence, len(name)) + name
    if secret is not None:
        envelope += _tag(secret, key_expr, envelope, payload)
    return envelope


def open_(attachment: "bytes | None", key_expr: str, payload: bytes, secret: "bytes | None" = None) -> Envelope:
    """The envelope of a message. With ``secret`` its tag must verify; without, a tagged envelope
    is refused too (its sender has keys this reader lacks), as a host of the deployment refuses it.
    Raises :class:`EnvelopeError`."""
    a = bytes(attachment or b"")
    if len(a) < 22 or a[:3] != b"KPE":
        raise EnvelopeError("no KPL envelope")
    if a[3] != 1:
        raise EnvelopeError(f"envelope version {a[3]}; this package reads 1")
    flags, incarnation, sequence, n = _HEAD.unpack_from(a, 4)
    if len(a) < 22 + n:
        raise EnvelopeError("the envelope is cut short")
    try:
        host = a[22 : 22 + n].decode("utf-8")
    except UnicodeDecodeError:
        raise EnvelopeError("the envelope's host name is not UTF-8") from None
    tag = a[22 + n :]
    tagged = bool(flags & _TAGGED)
    if secret is None:
        if tagged or tag:
            raise EnvelopeError("a tagged envelope, and no secret to verify it (give the deployment's keys)")
    else:
        if not tagged or len(tag) != 32:
            raise EnvelopeError("no tag, and the deployment has keys")
        if not hmac.compare_digest(tag, _tag(secret, key_expr, a[: 22 + n], payload)):
            raise EnvelopeError("the tag does not verify with the deployment's secret")
    return Envelope(host, incarnation, sequence, bool(flags & _UNFINISHED), secret is not None)


def _tag(secret: bytes, key_expr: str, envelope: bytes, payload: bytes) -> bytes:
    data = _DOMAIN + key_expr.encode("utf-8") + b"\x00" + envelope + bytes(payload)
    return hmac.new(secret, data, hashlib.sha256).digest()
