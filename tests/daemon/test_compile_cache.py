"""Missions compiled and verified before are loaded from the compile cache: the same text, task
files and compiler only; anything changed is compiled again, and a directory others may write to
is not used."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import pytest

from orccadd.automaton.language import parser
from orccadd.daemon import compile_cache, compile_worker
from orccadd.daemon.compile_cache import CompileCache
from orccadd.daemon.machine import Machine
from orccadd.robot import load_robot_config, with_backend
from orccadd.runtime import WallClock
from orccadd.types import CommandMode
from tests.daemon.conftest import ROBOT, ROOT, load_in, machine_on

MISSION = """mission Cached
resource arm
input Stop

task Go on arm from "move.toml"
  set traj.target_rad = [0.1, -1.0, 1.0, -1.2, -1.4, 0.2]
  post
end

main procedure Main
  handle
    do
      Go
    until Stop
  on fatal do
    safe
  end
end

safe procedure Acknowledge
  await Stop
end
"""


@pytest.fixture
def folder(tmp_path: Path) -> Path:
    """A mission and the task file it names, in a folder of their own."""
    (tmp_path / "m").mkdir()
    shutil.copy(ROOT / "configs/tasks/move_joints.toml", tmp_path / "m/move.toml")
    (tmp_path / "m/cached.mission").write_text(MISSION)
    return tmp_path / "m"


def compile_in_worker(folder: Path, cache: Path, out: Path) -> tuple[int, str]:
    """`compile_worker` on folder/cached.mission as the daemon starts it: its exit code and
    standard error; out.cached exists if it answered from the cache."""
    out.with_name(out.name + ".cached").unlink(missing_ok=True)
    fd = os.open(folder / "cached.mission", os.O_RDONLY)
    try:
        cmd = [
            sys.executable, "-m", "orccadd.daemon.compile_worker", "--fd", str(fd),
            "--name", str(folder / "cached.mission"), f"--task-dir={folder}", f"--cache-dir={cache}",
            str(out),
        ]  # fmt: skip
        r = subprocess.run(cmd, pass_fds=(fd,), capture_output=True, text=True, timeout=60, check=False)
    finally:
        os.close(fd)
    return r.returncode, r.stderr


def cached(out: Path) -> bool:
    return out.with_name(out.name + ".cached").exists()


def test_the_same_mission_is_answered_from_the_cache_with_the_same_answer(
    folder: Path, tmp_path: Path
) -> None:
    out = tmp_path / "answer.pickle"
    assert compile_in_worker(folder, tmp_path / "cache", out) == (0, "")
    assert not cached(out)
    first = out.read_bytes()
    assert compile_in_worker(folder, tmp_path / "cache", out) == (0, "")
    assert cached(out) and out.read_bytes() == first
    assert len(list((tmp_path / "cache").iterdir())) == 1


@pytest.mark.parametrize("change", ["the mission's text", "a task file it names"])
def test_anything_changed_is_compiled_again(folder: Path, tmp_path: Path, change: str) -> None:
    out = tmp_path / "answer.pickle"
    assert compile_in_worker(folder, tmp_path / "cache", out)[0] == 0
    if change == "the mission's text":
        (folder / "cached.mission").write_text(MISSION.replace("0.1, -1.0", "0.2, -1.0"))
    else:
        task = folder / "move.toml"
        task.write_text(task.read_text().replace("speed_scale = 0.8", "speed_scale = 0.7"))
    assert compile_in_worker(folder, tmp_path / "cache", out)[0] == 0
    assert not cached(out)
    assert compile_in_worker(folder, tmp_path / "cache", out)[0] == 0
    assert cached(out)  # and the new one is kept


def test_a_task_file_gone_or_a_damaged_entry_is_compiled_again(folder: Path, tmp_path: Path) -> None:
    out = tmp_path / "answer.pickle"
    assert compile_in_worker(folder, tmp_path / "cache", out)[0] == 0
    (entry,) = (tmp_path / "cache").iterdir()
    entry.write_bytes(entry.read_bytes()[:40])
    assert compile_in_worker(folder, tmp_path / "cache", out)[0] == 0
    assert not cached(out)
    (folder / "move.toml").unlink()
    code, _ = compile_in_worker(folder, tmp_path / "cache", out)
    assert code == 1 and not cached(out)  # refused as without a cache: the file is not there


def test_another_compiler_never_meets_an_entry(tmp_path: Path) -> None:
    cache = CompileCache(tmp_path)
    key = cache.key("/m/a.mission", b"mission A", ["/m"])
    assert key == CompileCache(tmp_path).key("/m/a.mission", b"mission A", ["/m"])
    other = CompileCache(tmp_path)
    other._code_id = "another orccadd"
    assert other.key("/m/a.mission", b"mission A", ["/m"]) != key
    for name, text, dirs in [("/m/b.mission", b"mission A", ["/m"]), ("/m/a.mission", b"mission A", ["/n"])]:
        assert cache.key(name, text, dirs) != key


def test_a_directory_others_may_write_to_is_not_used(folder: Path, tmp_path: Path) -> None:
    shared = tmp_path / "shared"
    shared.mkdir(mode=0o777)
    shared.chmod(0o777)
    assert "others may write to it" in CompileCache(shared).usable()
    out = tmp_path / "answer.pickle"
    for _ in range(2):
        code, err = compile_in_worker(folder, shared, out)
        assert code == 0 and not cached(out)
        assert "compile cache off" in err and "others may write to it" in err
    assert list(shared.iterdir()) == []


def test_a_new_directory_is_the_users_own(tmp_path: Path) -> None:
    d = tmp_path / "a" / "cache"
    assert CompileCache(d).usable() == ""
    assert d.stat().st_mode & 0o777 == 0o700


def test_the_oldest_entries_go_beyond_the_limit(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(compile_cache, "MAX_ENTRIES", 3)
    cache = CompileCache(tmp_path)
    for i in range(5):
        cache.store(f"k{i}", {}, b"answer")
        os.utime(tmp_path / f"k{i}", ns=(i * 10**9, i * 10**9))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["k2", "k3", "k4"]


def test_the_worker_reads_no_more_than_the_parser_takes() -> None:
    assert compile_worker.MAX_MISSION_CHARS == parser.MAX_MISSION_CHARS


@pytest.fixture
def machine_with_cache(tmp_path: Path, folder: Path) -> Iterator[Machine]:
    cfg = with_backend(load_robot_config(ROBOT), "sim")
    daemon = replace(
        cfg.daemon,
        mission_dirs=(str(folder),),
        task_dirs=(str(folder),),
        compile_cache_dir=str(tmp_path / "cc"),
    )
    with machine_on(replace(cfg, daemon=daemon), CommandMode.TORQUE, WallClock()) as m:
        yield m


def test_the_daemon_says_a_load_came_from_the_cache(machine_with_cache: Machine, folder: Path) -> None:
    first = load_in(machine_with_cache, folder / "cached.mission")
    again = load_in(machine_with_cache, folder / "cached.mission")
    assert isinstance(first, dict) and isinstance(again, dict)
    assert (first["cached"], again["cached"]) == (False, True)
    assert again["report"] == first["report"] and again["mission"] == first["mission"]
