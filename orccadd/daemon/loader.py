"""`load`'s work in the real-time process: the compiler process, its answer, the tasks built.

A mission is compiled and verified in a child process (`compile_worker`: never in this one,
whose interpreter lock the control thread needs), reading the mission from a descriptor this
process opened: a file of `daemon.mission_dirs` (`load`), or a mission the daemon wrote itself
(`orccadctl move`, `jog`, `follow`: `orccadd/daemon/adhoc.py`), which goes through the same
compiler, the same checks and the same refusals. One load at a time.
"""

from __future__ import annotations

import dataclasses
import gc
import os
import pickle
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Mapping
from pathlib import Path

from orccadd.automaton import Automaton, Network, Report
from orccadd.config.shipped import is_bare_name, is_file
from orccadd.confine import Confinement, ConfinementError
from orccadd.daemon import deploy
from orccadd.daemon.compile_cache import default_dir
from orccadd.daemon.mission import prepare_mission
from orccadd.daemon.replies import CommandError, Pending, Result
from orccadd.daemon.view import Machine
from orccadd.errors import OrccaddError
from orccadd.mission import check_on_robot
from orccadd.robot import create_resource
from orccadd.task.spec import TaskSpec
from orccadd.wire.schema import MachineState, OperatorAction, Trace

Compiled = tuple[Automaton | Network, Report, dict[str, TaskSpec]]  # the compiler's answer


class Loader:
    def __init__(self, machine: Machine) -> None:
        self.m = machine
        self._loading: subprocess.Popen[bytes] | None = None  # the compiler process of a load

    def close(self) -> None:
        """Stop a load's compiler process still running (the daemon is stopping): in a session of
        its own, it would outlive the daemon otherwise."""
        child = self._loading
        if child is not None and child.poll() is None:
            child.kill()
            child.wait()

    def check_free(self, what: str = "load a mission") -> None:
        """`CommandError` unless a mission may be loaded now."""
        self.m.mission.need(MachineState.IDLE, MachineState.READY, what=what)
        if self._loading is not None:
            raise CommandError("a mission is being loaded: wait for its answer")

    def load(self, path: str) -> Pending:
        """`load`: the mission file `path` names, in one of `daemon.mission_dirs`, or a deployed
        one by its name or hash (`deploy`)."""
        self.check_free()
        deployed = self._deployed(path)
        if deployed is not None:
            where, record = deployed
            fd = os.open(where / f"{record.name}.mission", os.O_RDONLY | os.O_CLOEXEC | os.O_NOFOLLOW)
            mission = str(where / f"{record.name}.mission")

            def installed(c: Compiled, cached: bool) -> Result:
                return {**self.install(mission, c, cached, deployment=record.hash), "deployment": record.hash}

            return self._compile(fd, mission, installed, (str(where),))
        fd, path = self._open_mission(path)
        return self._compile(fd, path, lambda c, cached: self.install(path, c, cached))

    def _deployed(self, ref: str) -> tuple[Path, deploy.Record] | None:
        """The deployment `ref` names, if it names no file of the mission directories."""
        if not deploy.NAME_RE.match(ref):
            return None
        dirs = [self.m.station.resolve(d) for d in self.m.station.daemon.mission_dirs]
        if any(is_file(d / f"{ref}.mission") for d in dirs):
            return None  # a shipped or installed mission of that name comes first
        return deploy.find(deploy.deploy_dir(self.m.station), ref)

    def deploy(self, name: str, mission: str, files: dict[str, str], by: str) -> Result | Pending:
        """`deploy`: checked as `load` checks a file, then stored (`orccadd/daemon/deploy.py`)."""
        self.check_free("deploy a mission")
        root = deploy.deploy_dir(self.m.station)
        staged = deploy.stage(root, name, mission, files)
        if isinstance(staged, Path):
            return {**_deployed(deploy.read_record(staged)), "stored": False}
        try:
            fd = os.open(staged.mission, os.O_RDONLY | os.O_CLOEXEC | os.O_NOFOLLOW)
        except OSError as e:
            deploy.discard(staged)
            raise CommandError(f"deploy: {e.strerror or e}") from None
        keep = self.m.station.daemon.deployments_kept

        def verified(c: Compiled, cached: bool) -> Result:
            # load's last check, on this robot: every task builds (its parameters, its joints),
            # on resources made from the config (built, not opened: the live ones are untouched)
            fresh = [create_resource(u.cfg) for u in self.m.units]
            built = check_on_robot(c[0], fresh, self.m.station.name)
            if not built.ok:
                raise CommandError("\n".join(x for x in (built.summary, built.explanation) if x))
            record = deploy.commit(root, staged, by, keep)
            self.m.note(f"deployed mission {name} ({record.hash[:12]}, by {record.by}): all checks passed")
            return {**_deployed(record), "stored": True, "report": c[1].format()}

        def refused() -> None:
            deploy.discard(staged)

        return self._compile(fd, str(staged.mission), verified, (str(staged.path),), on_fail=refused)

    def load_text(
        self,
        text: str,
        name: str,
        data: Mapping[str, object],
        then: Callable[[Result], Result],
    ) -> Pending:
        """A mission the daemon wrote (`name` for messages): compiled, verified and installed as
        a file's would be, its tasks given `data` (`Module.set_data`); `then(result)` once it is
        loaded (ad-hoc motion: start it)."""
        self.check_free()
        fd = os.memfd_create("orccadd-mission", os.MFD_CLOEXEC)
        try:
            os.write(fd, text.encode())
            os.lseek(fd, 0, os.SEEK_SET)
        except OSError:
            os.close(fd)
            raise
        return self._compile(fd, name, lambda c, cached: then(self.install(name, c, cached, data)))

    def _compile(
        self,
        fd: int,
        path: str,
        done: Callable[[Compiled, bool], Result],
        extra_dirs: tuple[str, ...] = (),
        on_fail: Callable[[], None] = lambda: None,
    ) -> Pending:
        """Start the compiler process on `fd` (closed here); a pending reply, `done(answer,
        cached)` once it has answered. `extra_dirs`: where else its task files may be (a
        deployment's own); `on_fail()` when it refuses or fails."""
        work = Path(tempfile.mkdtemp(prefix="orccadd-load-"))
        out = work / "result.pickle"
        cfg = self.m.station
        configured = (*cfg.daemon.task_dirs, *cfg.daemon.mission_dirs)
        task_dirs = [*extra_dirs, *(str(cfg.resolve(d)) for d in configured)]
        cmd = [
            sys.executable, "-m", "orccadd.daemon.compile_worker", "--fd", str(fd), "--name", path,
            *(f"--task-dir={d}" for d in task_dirs), f"--memory-mb={cfg.daemon.load_memory_mb}",
            f"--cache-dir={self._cache_dir()}", str(out),
        ]  # fmt: skip
        timeout_s = cfg.daemon.load_timeout_s
        try:
            child = subprocess.Popen(
                cmd,
                stdin=subprocess.DEVNULL,
                stdout=subprocess.DEVNULL,
                start_new_session=True,
                pass_fds=(fd,),
            )
        except OSError as e:
            shutil.rmtree(work, ignore_errors=True)
            on_fail()
            raise CommandError(f"{path}: cannot start the compiler process: {e.strerror or e}") from None
        finally:
            os.close(fd)
        self._loading = child

        def finished() -> None:
            self._loading = None
            shutil.rmtree(work, ignore_errors=True)

        def poll() -> Result | None:
            if child.poll() is None:
                return None
            try:
                return answered()
            except CommandError:
                on_fail()
                raise

        def answered() -> Result:
            cached = Path(f"{out}.cached").exists()
            try:
                result = pickle.loads(out.read_bytes()) if out.exists() else None
            except (pickle.UnpicklingError, AttributeError, ImportError, EOFError, TypeError) as e:
                raise CommandError(
                    f"{path}: the compiler process's answer cannot be read by this daemon "
                    f"({type(e).__name__}: {e}): is orccadd's code on disk newer than this daemon? restart it"
                ) from None
            finally:
                finished()
            if isinstance(result, str):
                raise CommandError(result)
            if not isinstance(result, tuple):
                raise CommandError(f"{path}: the compiler process failed (exit code {child.returncode})")
            return done(result, cached)

        def expire() -> Result:
            child.kill()
            child.wait()
            finished()
            on_fail()
            raise CommandError(
                f"{path}: not compiled and verified within {timeout_s:g} s (daemon.load_timeout_s); "
                "`orccadctl check` shows how far it gets"
            )

        return Pending(poll, time.monotonic_ns() + int(timeout_s * 1e9), expire)

    def _cache_dir(self) -> str:
        """The compile cache's directory ('' when off): `daemon.compile_cache_dir`, relative to
        the config, or the user's cache (`compile_cache.default_dir`)."""
        d = self.m.station.daemon
        if not d.compile_cache:
            return ""
        return str(self.m.station.resolve(d.compile_cache_dir) if d.compile_cache_dir else default_dir())

    def _open_mission(self, path: str) -> tuple[int, str]:
        """A descriptor of the mission file `path` names and its real path, if it is a regular
        file inside one of the configured mission directories (checked on the descriptor: no
        link swapped in after the check, no FIFO); `CommandError` otherwise, saying where
        missions may be, never what is elsewhere. The compiler reads that descriptor."""
        cfg = self.m.station
        dirs = [cfg.resolve(d) for d in cfg.daemon.mission_dirs]
        conf = Confinement(dirs, "mission file", "daemon.mission_dirs")
        if is_bare_name(path):  # `load demo`: the first <dir>/demo.mission of the mission directories
            path = next((str(d / f"{path}.mission") for d in dirs if is_file(d / f"{path}.mission")), path)
        try:
            return conf.open(path)
        except ConfinementError as e:
            raise CommandError(str(e)) from None

    def install(
        self,
        path: str,
        compiled: Compiled,
        cached: bool = False,
        data: Mapping[str, object] | None = None,
        deployment: str = "",
    ) -> Result:
        """Build the verified mission's tasks on this robot and make it the loaded one."""
        automaton, report, specs = compiled
        mc = self.m.mission
        mc.need(MachineState.IDLE, MachineState.READY, what="load a mission")
        try:
            bindings = {u.name: (u.task_resource, u.task_queue) for u in self.m.units}
            loaded = prepare_mission(path, automaton, report, bindings, self.m.registry, specs, data)
            for u in self.m.units:  # a unit process builds the same tasks (the same ids)
                u.load_mission(
                    {
                        "path": path,
                        "automaton": automaton,
                        "report": report,
                        "specs": specs,
                        "data": data,
                        "events": self.m.registry.names(),
                        "input_events": mc.input_events_of(u.task_resource, loaded),
                    }
                )
        except OrccaddError as e:
            raise CommandError(str(e)) from None
        if deployment:
            loaded = dataclasses.replace(loaded, deployment=deployment)
        mc.install(loaded)
        # the replaced mission's tasks hold reference cycles (modules and their ports, compiled
        # ticks) and native state (Ruckig, Pinocchio data); the automatic collector is off in
        # this process (no pause in a tick): free them here, outside any tick (~1 ms)
        gc.collect()
        self.m.pub.trace(Trace.COMMAND, self.m.now_s(), OperatorAction.LOAD)
        how = "all checks passed" + (", verified at an earlier load: compile cache" if cached else "")
        self.m.note(f"loaded mission {loaded.name} ({loaded.automaton.n_states} states, {how})")
        return {"mission": loaded.describe(), "report": loaded.report.format(), "cached": cached}


def _deployed(record: deploy.Record) -> Result:
    """A deployment's reply: its hash, name, who deployed it and when."""
    return {"deployed": record.hash, "name": record.name, "by": record.by, "at_utc": record.at_utc}
