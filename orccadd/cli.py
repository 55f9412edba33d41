"""Console entry points: `orccadd` (the daemon, next issue) and `orccadctl` (the client)."""

from __future__ import annotations

import argparse
import sys

from orccadd.ctl import offline


def orccadd_main() -> int:
    print("orccadd: the daemon is not built yet; try `python -m orccadd.demo`", file=sys.stderr)
    return 2


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="orccadctl", description="Check, draw and (soon) run orccadd missions."
    )
    sub = parser.add_subparsers(dest="command", required=True)
    offline.add_parsers(sub)
    return parser


def orccadctl_main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return offline.run(args)


if __name__ == "__main__":
    sys.exit(orccadctl_main())
