"""The zenoh key expressions of a deployment's streams (docs/streams.md, "Key expressions").

A stream between hosts is published on ``kpl/DEPLOYMENT/SPEC/PRODUCER`` (the producer's default
output) or ``kpl/DEPLOYMENT/SPEC/PRODUCER/PORT`` (a named output, such as a link's ``changes``).
Each name is one key chunk: ASCII letters, digits, ``_``, ``-`` and ``.`` stay, every other byte
of its UTF-8 is written ``%XX``, and the empty name is ``%``.
"""

from __future__ import annotations

import string

_KEEP = frozenset((string.ascii_letters + string.digits + "_-.").encode("ascii"))

#: The deployment name of a spec without one (``deploy { ... }``) and no ``--deployment``.
DEFAULT_DEPLOYMENT = "default"


def chunk(name: str) -> str:
    """One name as one key chunk."""
    if name == "":
        return "%"
    return "".join(chr(b) if b in _KEEP else f"%{b:02X}" for b in name.encode("utf-8"))


def stream(spec: str, producer: str, port: "str | None" = None, deployment: str = DEFAULT_DEPLOYMENT) -> str:
    """The key of a stream: ``spec`` is the spec's file stem, ``producer`` the process that produces
    it, ``port`` its named output if not the default one."""
    parts = ["kpl", chunk(deployment), chunk(spec), chunk(producer)]
    if port is not None:
        parts.append(chunk(port))
    return "/".join(parts)


def streams(spec: str, deployment: str = DEFAULT_DEPLOYMENT) -> str:
    """The key expression of every stream of a deployment (not its liveliness tokens)."""
    return f"kpl/{chunk(deployment)}/{chunk(spec)}/**"
