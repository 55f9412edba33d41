"""`orccadd.confine`: a file a client names is opened inside the allowed directories only,
checked on the descriptor (not on a path that may change), without blocking."""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest

from orccadd import confine
from orccadd.confine import Confinement, ConfinementError


@pytest.fixture
def dirs(tmp_path: Path) -> tuple[Path, Path]:
    inside, outside = tmp_path / "missions", tmp_path / "outside"
    inside.mkdir()
    outside.mkdir()
    (inside / "ok.mission").write_text("mission Ok\n")
    (outside / "secret.mission").write_text("root-only line\n")
    return inside, outside


def test_a_file_inside_is_read_and_its_real_path_given(dirs: tuple[Path, Path]) -> None:
    inside, _ = dirs
    data, real = Confinement([inside], "mission file", "daemon.mission_dirs").read(inside / "ok.mission", 100)
    assert data == b"mission Ok\n" and real == str(inside / "ok.mission")


def test_links_out_absent_files_and_fifos_are_refused_without_reading_them(dirs: tuple[Path, Path]) -> None:
    inside, outside = dirs
    conf = Confinement([inside], "mission file", "daemon.mission_dirs")
    (inside / "link.mission").symlink_to(outside / "secret.mission")
    (inside / "sub").symlink_to(outside)
    os.mkfifo(inside / "fifo.mission")
    cases = {
        inside / "link.mission": "are loaded from",
        inside / "sub" / "secret.mission": "are loaded from",
        outside / "secret.mission": "are loaded from",
        outside / "absent.mission": "are loaded from",  # outside: whether it exists is not said
        inside / "absent.mission": "no such mission file",
        inside / "fifo.mission": "not a regular file",  # not opened for a blocking read
        inside: "not a regular file",
    }
    for path, why in cases.items():
        t0 = time.monotonic()
        with pytest.raises(ConfinementError) as e:
            conf.read(path, 100)
        assert why in str(e.value) and "root-only" not in str(e.value), (path, e.value)
        assert time.monotonic() - t0 < 5.0
    with pytest.raises(ConfinementError, match="larger than 4 bytes"):
        conf.read(inside / "ok.mission", 4)


def test_a_link_swapped_in_after_the_path_was_checked_is_caught_on_the_descriptor(
    dirs: tuple[Path, Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    """The path check saw a directory; by the time of the open it is a link out (simulated: the
    check is shown the path as it was, the open meets the link). The descriptor's real path says
    where the file really is: refused. A link swapped in as the last component: never followed."""
    inside, outside = dirs
    conf = Confinement([inside], "mission file", "daemon.mission_dirs")
    (inside / "sub").symlink_to(outside)
    (inside / "last.mission").symlink_to(outside / "secret.mission")
    monkeypatch.setattr(confine.os.path, "realpath", lambda p: os.path.abspath(p))
    for path in (inside / "sub" / "secret.mission", inside / "last.mission"):
        with pytest.raises(ConfinementError, match="are loaded from") as e:
            conf.read(path, 100)
        assert "root-only" not in str(e.value)
