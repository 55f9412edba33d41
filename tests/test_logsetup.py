"""Process logging: plain lines on a terminal or file, `<N>`-prefixed lines for journald."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from orccadd.logsetup import ENV_LEVEL, LogSetupError, resolve_level, syslog_priority, under_journald

ROOT = Path(__file__).resolve().parents[1]

SCRIPT = """
import logging, sys, warnings
from orccadd.logsetup import setup_logging
setup_logging("orccadd.x")
setup_logging("orccadd.y", "ERROR")  # once per process: ignored
log = logging.getLogger("orccadd.x")
log.debug("hidden unless DEBUG")
log.info("msg")
log.warning("careful")
try:
    raise RuntimeError("boom")
except RuntimeError:
    log.exception("it failed")
logging.getLogger("can.foreign").info("a library's info stays out")
"""


def run(tmp_path: Path, journal: bool, **env: str) -> list[str]:
    """The script's stderr lines; with `journal`, JOURNAL_STREAM names its stderr file."""
    err = tmp_path / "stderr.txt"
    environ = {k: v for k, v in os.environ.items() if k not in ("JOURNAL_STREAM", ENV_LEVEL)}
    with err.open("w") as fh:
        if journal:
            st = os.fstat(fh.fileno())
            environ["JOURNAL_STREAM"] = f"{st.st_dev}:{st.st_ino}"
        subprocess.run(
            [sys.executable, "-c", SCRIPT],
            cwd=ROOT,
            env={**environ, **env},
            stderr=fh,
            timeout=30,
            check=True,
        )
    return err.read_text().splitlines()


def test_plain_lines_have_time_level_name_and_message(tmp_path: Path) -> None:
    lines = run(tmp_path, journal=False)
    assert re.fullmatch(r"\d\d:\d\d:\d\d\.\d{3} INFO orccadd\.x: msg", lines[0]), lines
    assert re.fullmatch(r"\d\d:\d\d:\d\d\.\d{3} WARNING orccadd\.x: careful", lines[1]), lines
    assert re.fullmatch(r"\d\d:\d\d:\d\d\.\d{3} ERROR orccadd\.x: it failed", lines[2]), lines
    assert lines[3] == "Traceback (most recent call last):" and lines[-1] == "RuntimeError: boom"
    assert not any("hidden" in ln or "foreign" in ln or "library" in ln for ln in lines)


def test_under_journald_each_line_carries_its_priority(tmp_path: Path) -> None:
    lines = run(tmp_path, journal=True)
    assert lines[:3] == ["<6>orccadd.x: msg", "<4>orccadd.x: careful", "<3>orccadd.x: it failed"]
    tb = lines[3:]
    assert tb[0] == "<3>Traceback (most recent call last):" and tb[-1] == "<3>RuntimeError: boom"
    assert all(ln.startswith("<3>") for ln in tb), tb


def test_a_journal_stream_that_is_not_stderr_gives_plain_lines(tmp_path: Path) -> None:
    lines = run(tmp_path, journal=False, JOURNAL_STREAM="1:2")
    assert lines[0].endswith(" INFO orccadd.x: msg"), lines


def test_the_level_comes_from_the_environment(tmp_path: Path) -> None:
    lines = run(tmp_path, journal=True, **{ENV_LEVEL: "debug"})
    assert lines[0] == "<7>orccadd.x: hidden unless DEBUG"
    assert run(tmp_path, journal=True, **{ENV_LEVEL: "ERROR"})[0] == "<3>orccadd.x: it failed"


def test_a_bad_level_variable_is_a_clear_error() -> None:
    with pytest.raises(LogSetupError) as e:
        resolve_level("INFO", {ENV_LEVEL: "verbose"})
    assert str(e.value) == (
        "ORCCADD_LOG_LEVEL='verbose' is not a log level (allowed: DEBUG, INFO, WARNING, ERROR, CRITICAL)"
    )
    assert resolve_level("INFO", {ENV_LEVEL: ""}) == 20  # empty: unset
    assert resolve_level(10, {}) == 10


def test_a_process_started_with_a_bad_level_says_so_and_exits_2() -> None:
    env = {**os.environ, ENV_LEVEL: "loud"}
    cmd = [sys.executable, "-m", "orccadd.vcan", "--port", "0"]
    p = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=30)
    assert p.returncode == 2 and "ORCCADD_LOG_LEVEL='loud' is not a log level" in p.stderr, p.stderr
    assert "Traceback" not in p.stderr and p.stdout == ""


def test_priorities_follow_syslog() -> None:
    assert [syslog_priority(n) for n in (10, 20, 30, 40, 50)] == [7, 6, 4, 3, 2]


def test_journald_detection_needs_a_matching_stderr(tmp_path: Path) -> None:
    with (tmp_path / "f").open("w") as fh:
        st = os.fstat(fh.fileno())
        assert under_journald(fh, {"JOURNAL_STREAM": f"{st.st_dev}:{st.st_ino}"})
        assert not under_journald(fh, {"JOURNAL_STREAM": f"{st.st_dev}:{st.st_ino + 1}"})
        assert not under_journald(fh, {"JOURNAL_STREAM": "garbage"})
        assert not under_journald(fh, {})
