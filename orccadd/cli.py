"""Console entry points. The daemon and its client arrive with the execution-machine issue."""

from __future__ import annotations

import sys


def orccadd_main() -> int:
    print("orccadd: the daemon is not built yet; try `python -m orccadd.demo`", file=sys.stderr)
    return 2


def orccadctl_main() -> int:
    print("orccadctl: the command daemon is not built yet", file=sys.stderr)
    return 2
