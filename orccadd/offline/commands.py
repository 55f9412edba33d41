"""Commands that need no daemon: check a mission, draw it, export it for spin, the module
catalogue, plot a log, compare two runs (`compare_cli`)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from orccadd.ctl.format import error_line
from orccadd.errors import MissionError, OrccaddError

# The compiler and verifier (lark, ...) are imported by the commands that use them, so that
# `orccadctl status` and the other online commands start in tens of milliseconds.

EXIT_OK, EXIT_FAILED, EXIT_ERROR = 0, 1, 2
GRAPH_FULL_MAX = 50  # states a full graph stays readable with
MISSION_HELP = "a mission file, or a shipped mission's name (demo, pick_place, ...)"
PROGRESS_LINE_S = 2.0  # a long compilation says how far it is this often (on a terminal)


def add_parsers(sub: Any) -> None:
    p = sub.add_parser("check", help="compile a mission and run every check (no daemon needed)")
    p.add_argument("file", help=MISSION_HELP)
    p.add_argument("--json", action="store_true", help="machine-readable verdicts")
    p.add_argument(
        "--strict",
        action="store_true",
        help="warnings (dead code) fail the check too (the daemon's load keeps them warnings)",
    )
    p.add_argument(
        "--max-states",
        type=int,
        default=200_000,
        metavar="N",
        help="refuse a mission whose automaton would have more states (default 200000)",
    )
    p.add_argument(
        "--language-only",
        action="store_true",
        help="the language's checks only, not whether this daemon can load it (another platform's mission); "
        "a `par` of independent branches too large for one automaton is verified as a network",
    )
    p.add_argument(
        "--config",
        default=None,
        help="the robot to build every task on, as load does (a robot config file or a shipped "
        "name; default: the service's, /etc/orccadd/robots/robot.toml, where it exists)",
    )
    p.set_defaults(func=cmd_check)
    g = sub.add_parser("graph", help="draw a mission's automaton, or an abstract view of it")
    g.add_argument("file", help=MISSION_HELP)
    g.add_argument(
        "--abstract",
        default="",
        help="comma-separated signals/tasks to keep (minimised by bisimulation); default for more than "
        f"{GRAPH_FULL_MAX} states: every task, success and safe",
    )
    g.add_argument("--full", action="store_true", help="the whole automaton, however large")
    g.add_argument("--faults", action="store_true", help="keep type 3 exceptions in the picture")
    g.add_argument("-o", "--output", required=True, help="out.svg, out.png, out.pdf or out.dot")
    g.set_defaults(func=cmd_graph)
    e = sub.add_parser("export-promela", help="write the mission as a Promela model for spin")
    e.add_argument("file", help=MISSION_HELP)
    e.add_argument("-o", "--output", default="-", help="file, or - for standard output")
    e.add_argument(
        "--property",
        action="append",
        help="assertions to include: safety, conflicts, properties (the mission's; default: all)",
    )
    e.add_argument(
        "--model",
        choices=("structure", "table", "lockstep"),
        default="structure",
        help="structure: written from the program's statements (default); table: replays the compiled "
        "automaton; lockstep: both, spin asserts they react alike",
    )
    e.set_defaults(func=cmd_export)
    m = sub.add_parser("modules", help="the module catalogue: ports, parameters, defaults and bounds")
    m.add_argument("--config", default="sim-ur5e", help="the robot that sizes them (file or shipped name)")
    m.set_defaults(func=cmd_modules)
    text = "plot a log (CSV or MCAP): a panel per signal group with its unit, the events named (no daemon)"
    p = sub.add_parser("plot", help=text, description=text)
    p.add_argument("log", help="a log, CSV or MCAP (`orccadctl log stop -o run.csv` copies both)")
    p.add_argument("-o", "--output", required=True, help="out.png or out.svg")
    p.add_argument("--signals", default="", help="comma-separated column prefixes (default: all)")
    p.add_argument("--format", choices=("png", "svg"), help="default: the output's suffix, else png")
    p.set_defaults(func=cmd_plot)
    from orccadd.offline.compare_cli import add_parser as add_compare

    add_compare(sub)
    from orccadd.offline.replay_cli import add_parser as add_replay

    add_replay(sub)


def cmd_plot(a: argparse.Namespace) -> int:
    from orccadd.offline.plot import plot_csv

    try:
        info = plot_csv(Path(a.log), Path(a.output), [s for s in a.signals.split(",") if s], a.format)
    except (OSError, ValueError) as e:
        print(error_line(str(e)), file=sys.stderr)
        return EXIT_ERROR
    print(info)
    return EXIT_OK


def cmd_modules(args: argparse.Namespace) -> int:
    from orccadd.offline.catalogue import catalogue

    print(catalogue(args.config))
    return EXIT_OK


def cmd_check(args: argparse.Namespace) -> int:
    from orccadd.automaton import Network, compile_file, verify, verify_network
    from orccadd.automaton.checks.verify import format_trace
    from orccadd.mission import check_mission
    from orccadd.task.spec import read_task_interface

    try:
        if args.language_only:
            a = compile_file(args.file, args.max_states, read_task_interface, _progress(), allow_network=True)
            report = verify_network(a) if isinstance(a, Network) else verify(a)
        else:
            a, report = check_mission(args.file, args.max_states, _progress())
            report.results.extend(_on_robot(a, args.config))
    except MissionError as e:
        if args.json:
            print(
                json.dumps(
                    {
                        "ok": False,
                        "error": {"file": e.file, "line": e.line, "col": e.col, "message": e.detail},
                    }
                )
            )
        else:
            print(error_line(str(e)), file=sys.stderr)
        return EXIT_FAILED
    report.strict = args.strict
    if args.json:
        print(json.dumps({
            "ok": report.ok,
            "mission": a.program.name,
            "states": a.n_states,
            "transitions": a.n_transitions,
            "network": report.title,
            "checks": [
                {"name": r.name, "ok": r.ok, "level": report.level(r), "summary": r.summary,
                 "explanation": r.explanation,
                 "counterexample": format_trace(r.automaton or report.automaton, r.counterexample,
                                                r.loop_start) if not r.ok else [],
                 "loop_start": None if r.ok or r.loop_start is None else r.loop_start + 1}
                for r in report.results
            ],
            "notes": report.warnings,
        }))  # fmt: skip
    else:
        print(report.format())
    return EXIT_OK if report.ok else EXIT_FAILED


STAND_IN_ROBOT = "sim-ur5e"  # sizes the modules whose parameter names `check` reads without a robot


def _on_robot(a: Any, config: str | None) -> list[Any]:
    """`load`'s checks on a robot (every task built on it: parameter names, shapes, bounds,
    joints): `config`'s, else the service's on this PC; without either, the parameter names
    alone (they do not depend on the robot) and a warning that says which checks did not run
    (never a silent ok)."""
    from orccadd.automaton.checks.verify import WARNING, CheckResult
    from orccadd.config.shipped import SERVICE_CONFIG, robot_config_path
    from orccadd.mission import check_on_robot, check_parameter_names
    from orccadd.robot import create_resource, load_station_config

    if config is None and not SERVICE_CONFIG.is_file():
        stand_in = load_station_config(robot_config_path(STAND_IN_ROBOT), check_model=False)
        names = check_parameter_names(a, create_resource(stand_in.resources[0]).model)
        return [
            names,
            CheckResult(
                "robot",
                False,
                "not checked: no --config and no service config here "
                f"({SERVICE_CONFIG}): the tasks' parameter values, shapes and bounds and their joints "
                "are load's checks on a robot; run `check --config ROBOT` (a file or a shipped name "
                "such as sim-ur5e)",
                level=WARNING,
            ),
        ]
    path = robot_config_path(config) if config is not None else SERVICE_CONFIG
    station = load_station_config(path, check_model=False)  # ConfigError: exit 2, naming file and key
    return [check_on_robot(a, [create_resource(r) for r in station.resources], station.name)]


def cmd_graph(args: argparse.Namespace) -> int:
    from orccadd.automaton import Network, compile_file
    from orccadd.automaton.checks.views import full_view, minimize, project, render, to_dot
    from orccadd.task.spec import read_task_interface

    a = compile_file(args.file, task_files=read_task_interface, progress=_progress(), allow_network=True)
    if isinstance(a, Network):
        return _graph_network(a, args)
    names = [n for n in args.abstract.split(",") if n.strip()]
    if not names and not args.full and a.n_states > GRAPH_FULL_MAX:  # unreadable in full
        names = [t.name for t in a.program.tasks] + ["success", "safe"]
        print(f"{a.n_states} states: the abstract view on {', '.join(names)} (--full for all)")
    lts = minimize(project(a, names, faults=args.faults)) if names else full_view(a, faults=args.faults)
    render(to_dot(lts, a.program.name), Path(args.output))
    print(f"{args.output}: {lts.n} states, {len(lts.edges)} transitions")
    return EXIT_OK


def _graph_network(net: Any, args: argparse.Namespace) -> int:
    """A network: the context's and each branch's automaton, each in full (they are small)."""
    from orccadd.automaton.checks.views import network_views, render, to_dot_network

    if args.abstract:
        raise OrccaddError(f"{args.file}: --abstract draws one automaton; this mission is {net.describe()}")
    render(to_dot_network(network_views(net, faults=args.faults), net.program.name), Path(args.output))
    print(f"{args.output}: {net.describe()}")
    return EXIT_OK


def cmd_export(args: argparse.Namespace) -> int:
    from orccadd.automaton import compile_file
    from orccadd.automaton.promela.export import PROPERTIES, export_model
    from orccadd.task.spec import read_task_interface

    unknown = sorted(set(args.property or ()) - set(PROPERTIES))
    if unknown:
        raise OrccaddError(f"--property {', '.join(unknown)}: unknown (properties: {', '.join(PROPERTIES)})")
    a = compile_file(args.file, task_files=read_task_interface)  # refuses what `check` refuses
    model = export_model(a, args.model, tuple(args.property) if args.property else PROPERTIES)
    if args.output == "-":
        sys.stdout.write(model)
    else:
        Path(args.output).write_text(model)
    return EXIT_OK


def _progress() -> Any:
    """On a terminal, a long compilation's count on stderr, a line every `PROGRESS_LINE_S`
    (Ctrl-C stops it: exit 130, no traceback)."""
    if not sys.stderr.isatty():
        return None
    shown = [0.0]

    def show(states: int, transitions: int, elapsed_s: float) -> None:
        if elapsed_s - shown[0] < PROGRESS_LINE_S:
            return
        shown[0] = elapsed_s
        rate = states / elapsed_s if elapsed_s > 0 else 0.0
        print(
            f"compiling: {states} states, {transitions} transitions ({rate:.0f} states/s, {elapsed_s:.0f} s)",
            file=sys.stderr,
            flush=True,
        )

    return show


def run(args: argparse.Namespace) -> int:
    try:
        if isinstance(getattr(args, "file", None), str):  # `check demo`: a shipped mission by name
            from orccadd.config.shipped import mission_path

            args.file = str(mission_path(args.file))
        code: int = args.func(args)
        return code
    except MissionError as e:
        print(error_line(str(e)), file=sys.stderr)
        return EXIT_FAILED
    except OrccaddError as e:
        print(error_line(str(e)), file=sys.stderr)
        return EXIT_ERROR
