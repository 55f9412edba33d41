"""`orccadctl [--robot R] deploy MISSION`: a mission and its task files from this workstation to
a daemon, which checks it as `load` does and keeps it by content (orccadd/daemon/deploy.py).

The task files are the ones the mission names (`from "..."`), read relative to the mission's own
directory as the compiler would; nothing else is sent. A refusal prints the daemon's words (the
failed checks and their counterexamples) and exits 1; exit 2 for what stops it on this side.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path
from typing import Any

from orccadd.cellnet.console import CellError
from orccadd.ctl.cell import RemoteClient
from orccadd.ctl.client import Client, ClientError, socket_help
from orccadd.ctl.format import error_line
from orccadd.wire.commands import COMMANDS, MAX_LINE, client_wait_s, encode
from orccadd.wire.schema import PROTOCOL_VERSION

EXIT_OK, EXIT_REFUSED, EXIT_ERROR = 0, 1, 2
FROM_RE = re.compile(r'\bfrom\s+"([^"\n]*)"')  # the daemon's own reading: orccadd/daemon/deploy.py


def add_parser(sub: Any) -> None:
    text = COMMANDS["deploy"].help.replace("`", "")
    p: argparse.ArgumentParser = sub.add_parser("deploy", help=text, description=text)
    p.add_argument("mission", help="the mission file on this workstation")
    p.add_argument("--name", default="", help="its name on the daemon (default: the file's stem)")
    p.add_argument("--socket", default=None, metavar="PATH", help=socket_help())
    p.add_argument("--json", action="store_true", help="print the daemon's JSON reply")
    p.set_defaults(func=run_deploy, online="deploy")


def request(mission: Path, name: str) -> dict[str, Any]:
    """The `deploy` arguments for `mission`: its text and every task file it names, read here;
    `ClientError` naming a file that cannot be read or a request too large for one line."""
    try:
        text = mission.read_text()
    except (OSError, UnicodeDecodeError) as e:
        raise ClientError(f"deploy: {mission}: {getattr(e, 'strerror', None) or e}") from None
    files = list(dict.fromkeys(FROM_RE.findall(text)))
    texts = []
    for f in files:
        path = (mission.parent / f) if not Path(f).is_absolute() else Path(f)
        try:
            texts.append(path.read_text())
        except (OSError, UnicodeDecodeError) as e:
            raise ClientError(
                f'deploy: {mission}: its task file "{f}" ({path}): {getattr(e, "strerror", None) or e}'
            ) from None
    args = {"name": name or mission.stem, "mission": text, "task_files": files, "task_texts": texts}
    size = len(encode({"id": 1, "cmd": "deploy", "args": args, "protocol": PROTOCOL_VERSION}))
    if size > MAX_LINE:
        raise ClientError(
            f"deploy: {mission} and its {len(files)} task files make a request of {size} bytes; "
            f"one request carries at most {MAX_LINE}"
        )
    return args


def run_deploy(a: argparse.Namespace) -> int:
    try:
        args = request(Path(a.mission), a.name)
        robot = getattr(a, "robot", None)
        with RemoteClient(a, robot) if robot else Client(a.socket, timeout_s=client_wait_s("deploy")) as c:
            r = c.reply("deploy", **args)
    except (ClientError, CellError) as e:
        print(error_line(str(e)), file=sys.stderr)
        return EXIT_ERROR
    except OSError as e:
        print(error_line(f"orccadd: {e.strerror or e}"), file=sys.stderr)
        return EXIT_ERROR
    if a.json:
        print(json.dumps(r, indent=1))
    elif not r.get("ok"):
        print(str(r.get("error")), file=sys.stderr)
    else:
        d = r["result"]
        how = "deployed" if d["stored"] else "already deployed"
        who = f"by {d['by']}, {d['at_utc']}"
        print(f"{how}: {d['name']} {d['deployed'][:12]} ({who}); `orccadctl load {d['name']}` loads it")
    return EXIT_OK if r.get("ok") else EXIT_REFUSED
