"""The layers hold: contracts kept, no import cycle, and the light processes stay light."""

from __future__ import annotations

import re
import subprocess
import sys
import tomllib
from pathlib import Path

import grimp

ROOT = Path(__file__).resolve().parents[1]
HEAVY = ("pinocchio", "canopen", "can", "ruckig", "lark", "matplotlib", "serial", "dynamixel_sdk")
OURS_HEAVY = ("orccadd.daemon", "orccadd.physres", "orccadd.task", "orccadd.modules", "orccadd.model")


def test_import_linter_contracts_are_kept() -> None:
    lint = Path(sys.executable).parent / "lint-imports"
    out = subprocess.run([str(lint)], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-2000:]


def strongly_connected(graph: dict[str, set[str]]) -> list[list[str]]:
    """Tarjan's algorithm, iteratively: the import cycles (components of more than one module)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    cycles: list[list[str]] = []
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            v, children = work[-1]
            for w in children:
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                    break
                if w in on_stack:
                    low[v] = min(low[v], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[v])
                if low[v] == index[v]:
                    comp = []
                    while True:
                        w = stack.pop()
                        on_stack.discard(w)
                        comp.append(w)
                        if w == v:
                            break
                    if len(comp) > 1:
                        cycles.append(sorted(comp))
    return cycles


def test_tarjan_finds_a_planted_cycle() -> None:
    assert strongly_connected({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert strongly_connected({"a": {"b"}, "b": set()}) == []


def test_no_import_cycle_in_orccadd() -> None:
    g = grimp.build_graph("orccadd", include_external_packages=False)
    graph = {m: set(g.find_modules_directly_imported_by(m)) for m in g.modules}
    assert strongly_connected(graph) == []


def loaded_after(code: str) -> list[str]:
    probe = f"{code}\nimport sys\nprint('\\n'.join(sorted(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", probe], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    return out.stdout.split()


def heavy(mods: list[str]) -> list[str]:
    return [m for m in mods if m.split(".")[0] in HEAVY or m.startswith(OURS_HEAVY)]


def test_the_command_daemon_loads_no_backend_model_or_machine() -> None:
    assert heavy(loaded_after("import orccadd.cmdd.server")) == []


def test_orccadctl_online_commands_load_neither_numpy_nor_the_compiler() -> None:
    code = "from orccadd.cli import build_parser\nbuild_parser().parse_args(['status'])"
    mods = loaded_after(code + "\nimport orccadd.ctl.online")
    assert heavy(mods) == []
    assert "numpy" not in mods


def contract_layers() -> list[set[str]]:
    """The layers of the import-linter contract (pyproject.toml), top first, without `orccadd.`."""
    conf = tomllib.loads((ROOT / "pyproject.toml").read_text())
    contract = next(c for c in conf["tool"]["importlinter"]["contracts"] if c["type"] == "layers")
    return [{m.strip().removeprefix("orccadd.") for m in line.split("|")} for line in contract["layers"]]


def documented_layers() -> list[set[str]]:
    """The packages of each row of docs/architecture.md's layer table, top first: the backticked
    names of orccadd's own packages, outside the parenthesised remarks."""
    ours = {p.stem for p in (ROOT / "orccadd").iterdir() if p.suffix == ".py" or (p / "__init__.py").exists()}
    text = (ROOT / "docs/architecture.md").read_text()
    table = text.split("| layer | packages | what it may import |", 1)[1].split("\n\n", 1)[0]
    rows = []
    for line in table.splitlines()[2:]:
        cell = line.split(" | ")[1]
        bare, depth, quoted = [], 0, False
        for ch in cell:  # drop "( … )" remarks, but not parentheses inside `code`
            quoted ^= ch == "`"
            depth += (ch == "(") - (ch == ")") if not quoted else 0
            bare.append(ch if depth == 0 else "")
        names = re.findall(r"`([^`]+)`", "".join(bare))
        rows.append({n.split(".")[0] for n in names} & ours)
    return rows


def test_the_contract_and_the_documented_layers_are_the_same_layers() -> None:
    assert documented_layers() == contract_layers()
    every = {
        p.stem for p in (ROOT / "orccadd").iterdir() if p.suffix == ".py" or (p / "__init__.py").exists()
    }
    assert every - {"__init__"} == set().union(*contract_layers())  # each package in exactly one layer
