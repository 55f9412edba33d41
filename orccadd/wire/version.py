"""What `--version` says: the package's version and the wire protocol's."""

from __future__ import annotations

from orccadd import __version__
from orccadd.wire.schema import PROTOCOL_VERSION


def version_text(prog: str = "orccadd") -> str:
    return f"{prog} {__version__} (protocol {PROTOCOL_VERSION})"
