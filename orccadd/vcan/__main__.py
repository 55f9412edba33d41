"""`python -m orccadd.vcan`: the userspace CAN hub (see `orccadd.vcan.hub`)."""

import sys

from orccadd.vcan.hub import main

__all__ = ["main"]

if __name__ == "__main__":
    sys.exit(main())
