"""Long fuzzing runs with the strategies of tests/fuzz (issue 15).

Target: 100,000 requests and 10,000 missions with 0 crashes, 0 tracebacks, the loop at rate
throughout. Runs hypothesis `@given` tests in rounds of a few hundred examples until the time is
up; each example's properties are checked as in tests/fuzz, and a violation is recorded (with
the smallest example seen for it) instead of stopping the run. Prints the counts, the
violations with their reproducers, the tracebacks in the daemon's log and the loop's tick period
(median/p99/max, from every tick of the shared-memory ring).

Usage: `python benchmarks/fuzz.py --minutes N [--target protocol|missions|configs|all]`
(`all`: 60 % of the time on the protocol, 30 % on missions, 10 % on configs).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import re
import shutil
import sys
import tempfile
import threading
import time
from collections import Counter
from collections.abc import Callable
from pathlib import Path

import numpy as np
from harness import figures
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from orccadd.ctl.client import Client
from orccadd.wire.schema import H, T
from orccadd.wire.telemetry import RingReader, TelemetryBlock
from tests.fuzz.strategies import configs, connections, missions
from tests.fuzz.target import Outcome, exchange, hostile_paths, start_fuzz_daemon
from tests.fuzz.test_config_fuzz import load_outcome
from tests.fuzz.test_mission_fuzz import compile_outcome

ROUND = settings(
    max_examples=300,
    deadline=None,
    database=None,
    derandomize=False,
    phases=[Phase.generate],
    suppress_health_check=list(HealthCheck),
)
SHARES = {"protocol": 0.6, "missions": 0.3, "configs": 0.1}
RATE_HZ = 500.0  # sim-ur5e


class Violations:
    """Property violations by kind (exception type + the message's first part, before ': ',
    numbers blanked: the checks of tests/fuzz write `<property>: <details>`), each with the
    shortest example that showed it."""

    def __init__(self) -> None:
        self.count: Counter[str] = Counter()
        self.example: dict[str, str] = {}

    def add(self, e: BaseException, example: object) -> None:
        first = (str(e).splitlines() or [""])[0]
        if isinstance(e, AssertionError):
            first = first.split(": ")[0]
        first = re.sub(r"\d+", "…", re.sub(r"/[^\s:'\"]*", "<path>", first))
        kind = f"{type(e).__name__}: {first[:120]}"
        self.count[kind] += 1
        text = repr(example)
        if kind not in self.example or len(text) < len(self.example[kind]):
            self.example[kind] = text

    def report(self) -> None:
        total = sum(self.count.values())
        print(f"  crashes / property violations: {total}")
        for kind, n in self.count.most_common():
            ex = self.example[kind]
            print(f"    {n} × {kind}\n      smallest example: {ex[:600]}{'…' if len(ex) > 600 else ''}")


def run_rounds(test: Callable[[], None], until: float) -> int:
    rounds = 0
    while time.monotonic() < until:
        test()
        rounds += 1
    return rounds


class TickSampler(threading.Thread):
    """Every tick's release time and wake-up latency, from the telemetry ring."""

    def __init__(self, telemetry: str) -> None:
        super().__init__(daemon=True)
        self.tel = TelemetryBlock.attach(telemetry)
        self.reader = RingReader(self.tel.ticks, self.tel.header, H.TICK_HEAD, from_now=True)
        self.t_s: list[np.ndarray] = []
        self.wake_us: list[np.ndarray] = []
        self.done = threading.Event()

    def run(self) -> None:
        while not self.done.wait(0.25):
            rec = self.reader.poll()
            self.t_s.append(rec[:, T.T_S])
            self.wake_us.append(rec[:, T.WAKE_US])

    def stop(self) -> None:
        self.done.set()
        self.join()
        self.tel.close()

    def report(self, elapsed_s: float) -> None:
        t = np.concatenate(self.t_s) if self.t_s else np.empty(0)
        periods_ms = np.diff(t) * 1e3
        print(
            f"  loop: {t.size} ticks in {elapsed_s:.1f} s ({t.size / elapsed_s:.0f}/s, rate {RATE_HZ:g} Hz)"
        )
        print(f"    tick period   {figures(periods_ms, 'ms', 3)}")
        print(f"    wake-up       {figures(np.concatenate(self.wake_us) if self.wake_us else [], 'µs')}")
        print(f"    ticks lost to the reader: {self.reader.lost}")


def fuzz_protocol(seconds: float, v: Violations) -> None:
    tmp = Path(tempfile.mkdtemp(prefix="orccadd-fuzz-"))
    d = start_fuzz_daemon(tmp)
    counts: Counter[str] = Counter()
    try:
        paths = hostile_paths(tmp)
        with Client(d.socket) as c:
            cmdd_pid = c.call("ping")["pid"]
            sampler = TickSampler(str(c.call("describe")["telemetry"]))
            ticks0, overruns0 = c.call("status")["ticks"], c.call("status")["overruns"]
        sampler.start()
        t0 = time.monotonic()
        until = t0 + seconds

        @ROUND
        @given(st.data())
        def one(data: st.DataObject) -> None:
            frames = data.draw(connections(paths))  # drawn first: hypothesis wants the same draws
            if time.monotonic() > until:
                return
            out = Outcome()
            try:
                exchange(d.socket, frames, out)
            except Exception as e:
                v.add(e, frames)
            counts["connections"] += 1
            counts["request lines"] += out.lines
            counts["stream lines"] += out.streamed
            counts["replies ok"] += sum(1 for r in out.replies if r.get("ok"))
            counts["replies error"] += sum(1 for r in out.replies if not r.get("ok"))
            counts["closed by a framing fault"] += out.closed

        run_rounds(one, until)
        elapsed = time.monotonic() - t0
        sampler.stop()
        with Client(d.socket) as c:
            st_ = c.call("status")
            same = c.call("ping")["pid"] == cmdd_pid
        print(f"protocol: {seconds:.0f} s against one orccadd (sim-ur5e, {RATE_HZ:g} Hz)")
        for k, n in counts.items():
            print(f"  {k}: {n}")
        print(f"  requests per second: {counts['request lines'] / elapsed:.0f}")
        alive = d.proc.poll() is None
        print(f"  orccadd alive: {alive}; command daemon the same process: {same}")
        print(f"  state at the end: {st_['state']}, faulted {st_['faulted']}")
        ticks, overruns = st_["ticks"] - ticks0, st_["overruns"] - overruns0
        print(f"  ticks: {ticks} (expected ~{elapsed * RATE_HZ:.0f}), overruns {overruns}")
        sampler.report(elapsed)
    finally:
        d.stop()
        log = d.log.read_text(errors="replace")
        tracebacks = log.count("Traceback")
        print(f"  tracebacks in the daemon's log: {tracebacks}")
        for m in sorted(set(re.findall(r"^(\w+(?:\.\w+)*(?:Error|Exception)\b.*)$", log, re.M)))[:10]:
            print(f"    {m[:200]}")
        shutil.rmtree(tmp, ignore_errors=True)


def fuzz_missions(seconds: float, v: Violations) -> None:
    counts: Counter[str] = Counter()
    until = time.monotonic() + seconds

    @ROUND
    @given(missions())
    def one(case: tuple[Path, str]) -> None:
        if time.monotonic() > until:
            return
        try:
            counts[compile_outcome(*case)] += 1
        except Exception as e:
            v.add(e, case)

    run_rounds(one, until)
    print(f"missions: {seconds:.0f} s: {sum(counts.values())} mutated missions, {dict(counts)}")


def fuzz_configs(seconds: float, v: Violations) -> None:
    counts: Counter[str] = Counter()
    until = time.monotonic() + seconds
    tmp = Path(tempfile.mkdtemp(prefix="orccadd-fuzzcfg-"))

    @ROUND
    @given(configs())
    def one(data: bytes) -> None:
        if time.monotonic() > until:
            return
        try:
            counts[load_outcome(tmp / "robot.toml", data)] += 1
        except Exception as e:
            v.add(e, data)

    try:
        with contextlib.redirect_stderr(io.StringIO()):  # the loader's warnings (bus load)
            run_rounds(one, until)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    print(f"configs: {seconds:.0f} s: {sum(counts.values())} mutated configs, {dict(counts)}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--minutes", type=float, default=10.0)
    ap.add_argument("--target", choices=[*SHARES, "all"], default="all")
    args = ap.parse_args()
    total = args.minutes * 60
    shares = SHARES if args.target == "all" else {args.target: 1.0}
    runners: dict[str, Callable[[float, Violations], None]] = {
        "protocol": fuzz_protocol,
        "missions": fuzz_missions,
        "configs": fuzz_configs,
    }
    found: dict[str, Violations] = {}
    for name, share in shares.items():
        found[name] = Violations()
        runners[name](total * share, found[name])
    for name, v in found.items():
        print(f"{name}:")
        v.report()
    return 1 if any(v.count for v in found.values()) else 0


if __name__ == "__main__":
    sys.exit(main())
