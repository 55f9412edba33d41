"""`orccadctl [--robot R] logs` and `fetch NAME -o DIR`: a daemon's runs brought back.

`logs` lists the daemon's logs; `fetch` copies a log's CSV and its MCAP parts into DIR, chunk by
chunk (orccadd/cmdd/logfetch.py), each file checked whole against the sha256 the daemon sends
with its last chunk: a file that does not match is removed and the fetch fails (exit 1). An
existing file in DIR is not overwritten unless --force. The read-only role suffices.
"""

from __future__ import annotations

import argparse
import base64
import hashlib
import json
import os
import sys
from pathlib import Path
from typing import Any

from orccadd.cellnet.console import CellError
from orccadd.ctl.cell import RemoteClient
from orccadd.ctl.client import Client, ClientError, socket_help
from orccadd.ctl.format import error_line, table
from orccadd.wire.commands import COMMANDS, client_wait_s

EXIT_OK, EXIT_FAILED, EXIT_ERROR = 0, 1, 2
CHUNK = 32 * 1024


def add_parsers(sub: Any) -> None:
    for name in ("logs", "fetch"):
        text = COMMANDS[name].help.replace("`", "")
        p: argparse.ArgumentParser = sub.add_parser(name, help=text, description=text)
        p.add_argument("--socket", default=None, metavar="PATH", help=socket_help())
        p.add_argument("--json", action="store_true", help="print the daemon's JSON replies")
        if name == "fetch":
            p.add_argument("log", help="the log's CSV, as `orccadctl logs` names it")
            p.add_argument(
                "-o", "--output", required=True, metavar="DIR", help="the directory to copy it into"
            )
            p.add_argument("--force", action="store_true", help="overwrite files of the same name in DIR")
        p.set_defaults(func=run, online=name)


def run(a: argparse.Namespace) -> int:
    robot = getattr(a, "robot", None)
    try:
        with RemoteClient(a, robot) if robot else Client(a.socket, timeout_s=client_wait_s(a.online)) as c:
            listed = c.call("logs")
            if a.online == "logs":
                print(json.dumps(listed, indent=1) if a.json else logs_words(listed))
                return EXIT_OK
            return fetch(c, listed, a.log, Path(a.output), a.force, a.json)
    except (ClientError, CellError) as e:
        print(error_line(str(e)), file=sys.stderr)
        return EXIT_ERROR
    except OSError as e:
        print(error_line(f"{e.filename or 'orccadd'}: {e.strerror or e}"), file=sys.stderr)
        return EXIT_ERROR


def logs_words(listed: dict[str, Any]) -> str:
    rows = [("log", "size", "started (UTC)", "mission", "result", "MCAP")]
    for lg in listed["logs"]:
        size = f"{lg['size'] / 1e6:.1f} MB" if lg["size"] >= 1e5 else f"{lg['size'] / 1e3:.1f} kB"
        result = "(being written)" if lg["writing"] else lg["result"] or "-"
        rows.append(
            (
                lg["name"],
                size,
                lg["start_utc"] or "-",
                lg["mission"] or "-",
                result,
                ", ".join(lg["mcap"]) or "-",
            )
        )
    if len(rows) == 1:
        return f"no logs in {listed['directory']}"
    return "\n".join(table(rows, ""))


def fetch(
    c: Client | RemoteClient, listed: dict[str, Any], name: str, out: Path, force: bool, as_json: bool
) -> int:
    log = next((lg for lg in listed["logs"] if lg["name"] == name), None)
    if log is None:
        names = ", ".join(lg["name"] for lg in listed["logs"]) or "none"
        raise ClientError(f"fetch: no log {name!r} on this daemon (its logs: {names})")
    out.mkdir(parents=True, exist_ok=True)
    copied = []
    for file in (log["name"], *log["mcap"]):
        target = out / file
        if target.exists() and not force:
            raise ClientError(f"fetch: {target} exists (--force overwrites it)")
        sha = fetch_file(c, file, target)
        copied.append({"file": str(target), "bytes": target.stat().st_size, "sha256": sha})
    if as_json:
        print(json.dumps({"fetched": copied}, indent=1))
    else:
        for f in copied:
            print(f"{f['file']}: {f['bytes']} bytes, sha256 {f['sha256'][:16]}… checked")
    return EXIT_OK


def fetch_file(c: Client | RemoteClient, name: str, target: Path) -> str:
    """Copy the daemon's `name` into `target` chunk by chunk; its sha256, checked against the
    daemon's (the partial file removed and `ClientError` if they differ)."""
    tmp = target.with_name(f".{target.name}.part")
    h = hashlib.sha256()
    with tmp.open("wb") as f:
        offset, expected = 0, ""
        while True:
            r = c.call("fetch", name=name, offset=offset, length=CHUNK)
            data = base64.b64decode(r["data"])
            f.write(data)
            h.update(data)
            offset += len(data)
            if "sha256" in r:
                expected = r["sha256"]
                break
            if not data:
                break
    if h.hexdigest() != expected:
        tmp.unlink(missing_ok=True)
        raise ClientError(
            f"fetch: {name}: the copy's sha256 {h.hexdigest()[:16]}… is not the daemon's "
            f"{expected[:16] or '(none sent)'}…: removed (the file changed while it was copied?)"
        )
    os.replace(tmp, target)
    return h.hexdigest()
