"""`orccadctl`, the client: its online commands (`orccadd.ctl`, light: no numpy) and those that
need no daemon (`orccadd.offline`, imported only when one runs). The daemon's entry point,
`orccadd`, is `orccadd.daemon.rtproc:main`."""

from __future__ import annotations

import argparse
import os
import sys

from orccadd.ctl import deploy, fetch, motion, online
from orccadd.ctl.completion import SHELLS
from orccadd.errors import did_you_mean
from orccadd.wire.version import version_text

EXIT_INTERRUPTED = 130  # Ctrl-C: 128 + SIGINT, as a shell reports it


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="orccadctl", description="Check, draw, run, monitor and tune orccadd missions."
    )
    parser.add_argument("--version", action="version", version=version_text("orccadctl"))
    # also after the subcommand (`orccadctl status --socket PATH`), where they take precedence
    parser.add_argument(
        "--socket",
        dest="global_socket",
        default=None,
        metavar="PATH",
        help="the daemon's socket ($ORCCADD_SOCKET)",
    )
    parser.add_argument(
        "--json", dest="global_json", action="store_true", help="print JSON replies (and errors)"
    )
    parser.add_argument(
        "--robot",
        default=None,
        metavar="NAME",
        help="send the command to this daemon of the cell (over Zenoh; see --cell)",
    )
    parser.add_argument(
        "--cell",
        dest="global_cell",
        default=None,
        metavar="FILE",
        help="the console's [cell] table, for --robot and `cell` ($ORCCADD_CELL)",
    )
    sub = parser.add_subparsers(dest="command", required=True)
    from orccadd.offline.commands import add_parsers as add_offline  # argparse only, until one runs

    add_offline(sub)
    online.add_parsers(sub)
    motion.add_parsers(sub)
    deploy.add_parser(sub)
    fetch.add_parsers(sub)
    from orccadd.ctl.cell import add_parser as add_cell

    add_cell(sub)
    p = sub.add_parser("completion", help="print a shell completion script (bash, zsh)")
    p.add_argument("shell", choices=SHELLS, help="the shell to complete for")
    return parser


def orccadctl_main(argv: list[str] | None = None) -> int:
    try:
        return _main(argv)
    except KeyboardInterrupt:  # every command: quietly, no traceback
        return EXIT_INTERRUPTED
    except BrokenPipeError:  # our reader left (`| head`): the socket's errors never get here
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # the interpreter's last flush writes nowhere
        return 0


def _main(argv: list[str] | None) -> int:
    parser = build_parser()
    unknown = _unknown_command(parser, sys.argv[1:] if argv is None else argv)
    if unknown:
        print(f"{parser.prog}: error: {unknown}", file=sys.stderr)
        return 2
    args = parser.parse_args(motion.joined_values(sys.argv[1:] if argv is None else argv))
    if args.command == "completion":
        from orccadd.ctl.completion import completion_script

        sys.stdout.write(completion_script(parser, args.shell))
        return 0
    if args.global_socket and getattr(args, "socket", None) is None and hasattr(args, "socket"):
        args.socket = args.global_socket
    if args.global_json and hasattr(args, "json"):
        args.json = True
    if args.global_cell and getattr(args, "cell", None) is None:
        args.cell = args.global_cell
    if getattr(args, "online", None):
        code: int = args.func(args)
        return code
    from orccadd.offline.commands import run

    return run(args)


def _unknown_command(parser: argparse.ArgumentParser, argv: list[str]) -> str:
    """The words for a command orccadctl does not have, with the nearest ones ("" when known):
    one line, not the usage and every choice."""
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    words = iter(argv)
    for word in words:
        if word in ("--socket", "--robot", "--cell"):
            next(words, None)  # its value
        elif not word.startswith("-"):
            if word in sub.choices:
                return ""
            hint = did_you_mean(word, sub.choices) or f"; commands: {', '.join(sub.choices)}"
            return f"no command {word!r}{hint}"
    return ""


if __name__ == "__main__":
    sys.exit(orccadctl_main())
