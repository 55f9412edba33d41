"""Console entry points: `orccadd` (the real-time daemon) and `orccadctl` (the client)."""

from __future__ import annotations

import argparse
import sys

from orccadd.ctl import offline, online
from orccadd.wire.version import version_text


def orccadd_main() -> int:
    from orccadd.daemon.rtproc import main

    return main()


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="orccadctl", description="Check, draw, run, monitor and tune orccadd missions."
    )
    parser.add_argument("--version", action="version", version=version_text("orccadctl"))
    sub = parser.add_subparsers(dest="command", required=True)
    offline.add_parsers(sub)
    online.add_parsers(sub)
    return parser


def orccadctl_main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if getattr(args, "online", None) or args.command == "plot":
        code: int = args.func(args)
        return code
    return offline.run(args)


if __name__ == "__main__":
    sys.exit(orccadctl_main())
