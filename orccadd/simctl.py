"""`python -m orccadd.simctl CONTROL status|inject ...`: a device simulator's control channel from
a shell, what a test does with `SimulatorProcess.inject` and `.status`.

CONTROL is the address the simulator's ready line names (`ursim: ready, control 127.0.0.1:PORT`;
dxlsim's is a UNIX socket's path). `inject FAULT [--device N] [KEY=VALUE ...]` sends
`{"inject": FAULT, "device": N, KEY: VALUE, ...}` (VALUE read as JSON when it is one: `3`,
`true`, `[0.5,0,0.2]`, quoted in a shell: `'point_m=[0.5,0,0.2]'`; else as a string) and prints
the simulator's reply as JSON; `status` prints the simulator's state in words (`--json`: its
reply). A refusal prints the simulator's own words, exit 1; a channel nobody answers on, or bad
arguments, exit 2. The protocol: `orccadd.runtime.sim_control`; the client:
`orccadd.simproc.control_request`. Standard library only.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Sequence
from typing import Any

from orccadd.simproc import control_address, control_request

PROG = "python -m orccadd.simctl"
RESERVED = ("inject", "device")

# What each simulator's `inject` takes: (FAULT, its parameters as written in --help). The names
# are each simulator's own FAULTS (tests/test_simctl.py compares them); docs/simulators.md and
# the simulators' modules (orccadd.ursim.faults, orccadd.drivesim, orccadd.dxlsim.control,
# orccadd.plantsim.control) say what each does.
FAULTS: dict[str, tuple[str, tuple[tuple[str, str], ...]]] = {
    "ursim": (
        "a UR controller (python -m orccadd.ursim); no --device",
        (
            ("protective_stop", "[reason=TEXT]"),
            ("emergency_stop", ""),
            ("emergency_stop_release", ""),
            ("stream_stall", "duration_s=S"),
            ("drop_connection", "ports=rtde|dashboard|script|all"),
            ("controller_restart", "down_s=S"),
            ("wall", "point_m=[X,Y,Z] normal=[X,Y,Z] stiffness_n_m=K [damping_n_s_m=D]"),
            ("wall_remove", ""),
            ("push", "[force_n=[X,Y,Z]] [torque_nm=[X,Y,Z]] duration_s=S"),
            ("plane", "point_m=[X,Y,Z] normal=[X,Y,Z] stiffness_n_m=K [damping_n_s_m=D] [friction=MU]"),
            ("hole", "center_m=[X,Y,Z] normal=[X,Y,Z] radius_m=R stiffness_n_m=K [depth_m=H]"),
            ("tool", "radius_m=R"),
            ("clear_world", ""),
            ("digital_input", "index=0..7 value=true|false"),
            ("configurable_digital_input", "index=0..7 value=true|false"),
            ("tool_digital_input", "index=0..1 value=true|false"),
            ("ft_noise", "[force_n=STD] [torque_nm=STD] [seed=N]"),
            ("speed_slider", "fraction=0..1"),
        ),
    ),
    "drivesim": (
        "CiA 402 drives (python -m orccadd.drivesim); --device NODE_ID",
        (
            ("overcurrent", "[bus=CHANNEL]"),
            ("following_error", "[bus=CHANNEL]"),
            ("heartbeat_silence", "[bus=CHANNEL]"),
            ("node_silence", "[bus=CHANNEL]"),
            ("sto", "[bus=CHANNEL]"),
            ("clear", "[bus=CHANNEL]"),
        ),
    ),
    "dxlsim": (
        "DYNAMIXEL servos (python -m orccadd.dxlsim); --device SERVO_ID where one servo is meant",
        (
            ("overload", "--device ID"),
            ("overheating", "--device ID"),
            ("unplug", "--device ID"),
            ("replug", "--device ID"),
            ("noise", "rate=0..1"),
            ("late", "ms=MS [packets=N]"),
            ("object", "--device ID at_rad=RAD [stiffness_nm_rad=K] [closing=1|-1]"),
            ("remove_object", "--device ID"),
            ("clear", ""),
        ),
    ),
    "plantsim": (
        "the simulated arm's plant (sim_process; address: the resource's `plant_control`); no --device",
        (
            (
                "plane",
                "point_m=[X,Y,Z] normal=[X,Y,Z] stiffness_n_m=K [damping_n_s_m=D] [friction=MU] "
                "[viscous_friction_n_s_m=B]",
            ),
            (
                "hole",
                "center_m=[X,Y,Z] normal=[X,Y,Z] radius_m=R stiffness_n_m=K [depth_m=H] [damping_n_s_m=D] "
                "[friction=MU] [viscous_friction_n_s_m=B]",
            ),
            ("clear_world", ""),
            ("occlude", ""),
            ("unocclude", ""),
            ("target", "points_m=[[X,Y,Z],[X,Y,Z],[X,Y,Z],[X,Y,Z]]"),
        ),
    ),
}

EXAMPLES = """\
examples:
  python -m orccadd.simctl 127.0.0.1:30100 status
  python -m orccadd.simctl 127.0.0.1:30100 inject wall \\
      'point_m=[0,0,0.38]' 'normal=[0,0,1]' stiffness_n_m=5000
  python -m orccadd.simctl 127.0.0.1:30100 inject digital_input index=0 value=true
  python -m orccadd.simctl 127.0.0.1:30200 inject overcurrent --device 3    (drivesim --control-port 30200)
  python -m orccadd.simctl /tmp/orccadd-gripper.control inject object --device 1 at_rad=0.9
  python -m orccadd.simctl 127.0.0.1:30300 inject hole \
      'center_m=[0.5,0,0.1]' 'normal=[0,0,1]' radius_m=0.01 stiffness_n_m=20000    (plantsim)
"""


def faults_help() -> str:
    """The faults of every simulator, as --help lists them."""
    lines = ["faults (FAULT and its KEY=VALUE parameters, [optional]), by simulator:"]
    for sim, (what, faults) in FAULTS.items():
        lines.append(f"  {sim}: {what}")
        lines += [f"    {name:<28}{params}".rstrip() for name, params in faults]
    return "\n".join(lines)


def parse_param(text: str) -> tuple[str, Any]:
    """`KEY=VALUE` -> (KEY, VALUE read as JSON, or the text itself when it is not JSON)."""
    key, sep, raw = text.partition("=")
    if not sep or not key.isidentifier():
        raise argparse.ArgumentTypeError(
            f"parameter {text!r} must be KEY=VALUE, KEY a name (duration_s=1.0, point_m=[0.5,0,0.2])"
        )
    if key in RESERVED:
        raise argparse.ArgumentTypeError(
            f"parameter {key!r} is not allowed as KEY=VALUE: "
            + ("the fault is the FAULT argument" if key == "inject" else "give the device as --device N")
        )
    try:
        return key, json.loads(raw)
    except ValueError:
        return key, raw


def _address(text: str) -> str:
    try:
        control_address(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None
    return text


def _seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not 0.0 < value < math.inf:
        raise argparse.ArgumentTypeError(f"--timeout-s (={text!r}) must be a number of seconds above 0")
    return value


def parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog=PROG,
        description=__doc__,
        epilog=f"{faults_help()}\n\n{EXAMPLES}",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    ap.add_argument(
        "control",
        metavar="CONTROL",
        type=_address,
        help="127.0.0.1:PORT or a socket's path: the ready line's `control`",
    )
    ap.add_argument("--timeout-s", type=_seconds, default=10.0, help="how long to wait for the reply (10 s)")
    sub = ap.add_subparsers(dest="command", required=True, metavar="{status,inject}")
    st = sub.add_parser("status", help="the simulator's state (q_rad, dq_rad_s, devices, its own)")
    st.add_argument("--json", action="store_true", help="the reply as JSON")
    inj = sub.add_parser(
        "inject",
        help="a fault, a change of the world or of an input",
        epilog=faults_help(),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    inj.add_argument("fault", metavar="FAULT")
    inj.add_argument("--device", type=int, help="the device: a drive's node id, a servo's ID")
    inj.add_argument("params", metavar="KEY=VALUE", nargs="*", type=parse_param)
    return ap


def request_of(args: argparse.Namespace, ap: argparse.ArgumentParser) -> dict[str, Any]:
    """The protocol's request for the parsed command line (a parameter twice is an error)."""
    if args.command == "status":
        return {"status": True}
    req: dict[str, Any] = {"inject": args.fault}
    if args.device is not None:
        req["device"] = args.device
    for key, value in args.params:
        if key in req:
            ap.error(f"parameter {key!r} given twice")
        req[key] = value
    return req


def _value_words(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:.6g}"
    if isinstance(value, list) and value and all(isinstance(v, float | int) for v in value):
        return " ".join(f"{v:.4f}" if isinstance(v, float) else str(v) for v in value)
    if isinstance(value, dict):
        return ", ".join(f"{k} {_value_words(v)}" for k, v in value.items()) or "-"
    if isinstance(value, str):
        return value or "-"
    return json.dumps(value)


def status_words(reply: dict[str, Any]) -> list[str]:
    """A status reply in lines: `q_rad`, `dq_rad_s`, each device, then the simulator's own keys."""
    lines = []
    for key in ("q_rad", "dq_rad_s"):
        if key in reply:
            lines.append(f"{key:<24}{_value_words(reply[key])}")
    for dev in reply.get("devices", []):
        fault = f", fault: {dev['fault']}" if dev.get("fault") else ""
        lines.append(f"{'device ' + str(dev.get('id')):<24}{dev.get('state')}{fault}")
    for key, value in reply.items():
        if key not in ("ok", "q_rad", "dq_rad_s", "devices"):
            lines.append(f"{key:<24}{_value_words(value)}")
    return lines


def main(argv: Sequence[str] | None = None) -> int:
    ap = parser()
    args, extra = ap.parse_known_args(argv)
    for word in extra:  # KEY=VALUE after an option (`object --device 1 at_rad=0.9`)
        if args.command != "inject" or word.startswith("-"):
            ap.error(f"unrecognized argument {word!r} (see --help)")
        try:
            args.params.append(parse_param(word))
        except argparse.ArgumentTypeError as e:
            ap.error(f"argument KEY=VALUE: {e}")
    req = request_of(args, ap)
    try:
        reply = control_request(args.control, req, args.timeout_s)
    except (OSError, ValueError) as e:
        why = e.strerror if isinstance(e, OSError) and e.strerror else str(e) or type(e).__name__
        print(
            f"{PROG}: error: no answer from the simulator's control channel {args.control} ({why}): "
            "is the simulator running? its ready line names the address",
            file=sys.stderr,
        )
        return 2
    if not reply.get("ok"):
        print(f"{PROG}: error: {reply.get('error', 'refused, without a reason')}", file=sys.stderr)
        return 1
    if args.command == "status" and not args.json:
        print("\n".join(status_words(reply)))
    else:
        print(json.dumps(reply))
    return 0


if __name__ == "__main__":
    sys.exit(main())
