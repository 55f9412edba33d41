"""A logged run of a mission on a test daemon, for the tests that read runs back (compare, replay)."""

from __future__ import annotations

from pathlib import Path

from tests.daemon.conftest import Daemon


def logged_run(
    d: Daemon, mission: str, out: Path | None, *signals: str, tune: tuple[str, str] | None = None
) -> Path:
    """One run of `mission` to its success, logged to `out` (`signals`; none: the daemon's default)
    from before its start, `tune` applied first; its MCAP. `out` None: run, not logged."""
    assert d.ctl("load", mission).returncode == 0
    if out is not None:
        r = d.ctl("log", "start", *signals, "--name", out.name)
        assert r.returncode == 0, r.stderr
    if tune is not None:
        assert d.ctl("tune", *tune).returncode == 0
    assert d.ctl("start").returncode == 0
    s = d.wait(lambda s: s["state"] != "running", timeout_s=60)
    assert s["result"] == "success", s
    if out is None:
        return Path()
    r = d.ctl("log", "stop", "-o", str(out))
    assert r.returncode == 0, r.stderr
    return out.with_suffix(".mcap")
