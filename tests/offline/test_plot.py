"""`orccadctl plot`: a panel per signal group with its unit, the events marked with their names,
PNG or SVG; a log written by the command daemon's own writer (from a stand-in telemetry block)."""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from orccadd.cli import orccadctl_main
from orccadd.cmdd.csvlog import LogDir
from orccadd.cmdd.logsession import LogSource, TelemetryLog
from orccadd.cmdd.views import SignalSelection
from orccadd.offline.plot import LANE_ROWS, lane_rows, output_format, plot_csv, read_log
from orccadd.wire.schema import CommandMode, Layout, OperatorAction, Trace
from orccadd.wire.telemetry import TelemetryBlock
from tests.cmdd.conftest import DESC, PERIOD_S, URDF, FakeLoop, decode

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture
def log(tmp_path: Path) -> Iterator[Path]:
    """A short log: q, dq, tau, cmd and wake_us; a start, an instant, a task event, a change of
    command mode (torque, then position)."""
    tel = TelemetryBlock.create(Layout(dof=2, tick_len=1024, trace_len=16), PERIOD_S)
    try:
        loop = FakeLoop(tel)
        loop.ticks(5)
        sel = SignalSelection(["q", "dq", "tau", "cmd", "wake_us"], DESC["joints"])
        rec = TelemetryLog.start(
            LogDir(tmp_path / "logs", ""),
            [LogSource("", tel, sel)],
            tel,  # the trace: the daemon's own block, the resource's here
            "run.csv",
            lambda: DESC,
            decode,
            URDF,
            {},
        )
        loop.ticks(50)
        loop.trace(Trace.COMMAND, OperatorAction.START)
        loop.trace(Trace.INSTANT, inputs=(0,), actions=(0,))
        rec.pump()
        loop.ticks(50)
        loop.trace(Trace.EVENT, 0)  # Approach.T1.TrackingDrift
        loop.mode = CommandMode.POSITION
        loop.ticks(50)
        rec.close()
    finally:
        tel.close()
    yield tmp_path / "logs/run.csv"


def test_an_svg_names_the_events_and_the_units_of_every_axis(log: Path, tmp_path: Path) -> None:
    out = tmp_path / "run.svg"
    info = plot_csv(log, out, [])
    text = out.read_text()
    assert text.lstrip().startswith("<?xml") and "<svg" in text and text.rstrip().endswith("</svg>")
    for label in ("q [rad]", "dq [rad/s]", "tau [N.m]", "wake_us [us]", "time since the log started [s]"):
        assert label in text, label
    assert "cmd [N.m | rad]" in text and re.search(r">\s*position\s*<", text)  # the mode's change marked
    for name in ("start", "Approach.T1.TrackingDrift"):
        assert re.search(rf">\s*{re.escape(name)}\s*<", text), name
    assert "5 plots, 150 samples" in info and "3 events" in info and "(svg)" in info


def test_a_png_by_default_or_by_suffix(log: Path, tmp_path: Path) -> None:
    assert orccadctl_main(["plot", str(log), "-o", str(tmp_path / "run.png"), "--signals", "q"]) == 0
    assert orccadctl_main(["plot", str(log), "-o", str(tmp_path / "run.out"), "--signals", "q"]) == 0
    assert (
        orccadctl_main(["plot", str(log), "-o", str(tmp_path / "x.png"), "--format", "svg", "--signals", "q"])
        == 0
    )
    for name in ("run.png", "run.out"):
        assert (tmp_path / name).read_bytes()[:8] == PNG_MAGIC
    assert b"<svg" in (tmp_path / "x.png").read_bytes()[:500]  # --format wins over the suffix
    assert [output_format(Path(p), None) for p in ("a.svg", "a.SVG", "a.png", "a.pdf", "a")] == [
        "svg",
        "svg",
        "png",
        "png",
        "png",
    ]


def test_a_log_without_a_header_still_plots(tmp_path: Path) -> None:
    """An old log: absolute times, no units, no events."""
    old = tmp_path / "old.csv"
    old.write_text("time_s,q.j1\r\n1000.002000,1\r\n1000.004000,2\r\n")
    d = read_log(old)
    assert d.data[:, 0].tolist() == pytest.approx([0.0, 0.002]) and not d.events
    out = tmp_path / "old.svg"
    plot_csv(old, out, [])
    assert "q [unit not recorded]" in out.read_text()


def test_not_a_log_is_refused(tmp_path: Path) -> None:
    bad = tmp_path / "bad.csv"
    bad.write_text("a,b\n1,2\n")
    with pytest.raises(ValueError, match="not an orccadd log"):
        plot_csv(bad, tmp_path / "x.png", [])
    assert orccadctl_main(["plot", str(bad), "-o", str(tmp_path / "x.png")]) == 2


def test_the_mcap_of_a_log_reads_and_plots_as_its_csv(log: Path, tmp_path: Path) -> None:
    csv_log, mcap_log = read_log(log), read_log(log.with_suffix(".mcap"))
    assert mcap_log.columns == csv_log.columns
    assert mcap_log.data == pytest.approx(csv_log.data)  # same rows, same times since the start
    assert {k: v for k, v in mcap_log.units.items() if k in csv_log.units} == csv_log.units
    named = [(kind, name) for _, kind, name in csv_log.events]
    assert [(kind, name) for _, kind, name in mcap_log.events] == named
    assert [t for t, _, _ in mcap_log.events] == pytest.approx([t for t, _, _ in csv_log.events], abs=1e-6)
    out = tmp_path / "from_mcap.svg"
    assert orccadctl_main(["plot", str(log.with_suffix(".mcap")), "-o", str(out)]) == 0
    assert "cmd [N.m | rad]" in out.read_text()


def test_a_file_neither_csv_nor_mcap_is_refused_in_words(tmp_path: Path) -> None:
    binary = tmp_path / "x.mcap"
    binary.write_bytes(b"\x89MCAP0\r\n" + b"\xff" * 64)  # the magic, then nothing readable
    with pytest.raises(ValueError, match="not a readable MCAP log"):
        read_log(binary)
    blob = tmp_path / "x.bin"
    blob.write_bytes(bytes(range(256)))
    with pytest.raises(ValueError, match="neither its CSV nor its MCAP"):
        read_log(blob)


def test_event_names_close_together_take_rows_of_their_own() -> None:
    # the demo's events at 0, 0.8, 1.75 and 3.1 s over 8 s, with long names: they used to pile up
    marks = [
        (t, "instant", f"Reach.T2.TrackingLost+Home.done #{i}") for i, t in enumerate((0, 0.05, 0.1, 3.1))
    ]
    rows = lane_rows(marks, 0.0, 8.0, 8.0)
    assert rows == [0, 1, 2, 0]  # three close ones stacked, the far one back on the first row
    crowd = [(i * 0.001, "event", "X.T1.Slow") for i in range(40)]
    crowded = lane_rows(crowd, 0.0, 8.0, 8.0)
    assert max(crowded) == LANE_ROWS - 1 and crowded.count(-1) == 40 - LANE_ROWS  # counted, not drawn


def test_legends_stand_beside_the_panels(log: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from matplotlib.figure import Figure

    saved: list[Figure] = []
    real = Figure.savefig

    def keep(fig: Figure, *args: Any, **kwargs: Any) -> None:
        fig.canvas.draw()
        saved.append(fig)
        real(fig, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", keep)
    plot_csv(log, tmp_path / "run.png", ["q", "tau"])
    panels = [ax for ax in saved[0].axes if ax.get_legend() is not None]
    assert len(panels) == 2
    for ax in panels:  # the legend's box starts right of the panel's: it covers no trace
        legend = ax.get_legend()
        assert legend is not None and legend.get_window_extent().x0 >= ax.get_window_extent().x1


def test_a_cells_log_under_the_name_given_to_log_stop_plots_from_its_mcap(log: Path, tmp_path: Path) -> None:
    """`log stop -o run.csv` of a cell writes run.left.csv, run.right.csv and run.mcap: `plot
    run.csv` plots the MCAP (every resource); without it, the error names the parts."""
    cell = tmp_path / "cell"
    cell.mkdir()
    for part in ("run.left.csv", "run.right.csv"):
        (cell / part).write_bytes(log.read_bytes())
    parts = r"run.csv: no such file; this log is in 2 parts: .*run.left.csv"
    with pytest.raises(FileNotFoundError, match=parts):
        plot_csv(cell / "run.csv", tmp_path / "x.png", [])
    (cell / "run.mcap").write_bytes(log.with_suffix(".mcap").read_bytes())
    info = plot_csv(cell / "run.csv", tmp_path / "x.png", [])
    assert "from " in info and "run.mcap" in info and (tmp_path / "x.png").read_bytes()[:8] == PNG_MAGIC
    with pytest.raises(FileNotFoundError, match=r"nothing.csv: no such file$"):
        plot_csv(cell / "nothing.csv", tmp_path / "x.png", [])


def test_a_signal_name_selects_it_on_every_resource_of_a_cell(tmp_path: Path) -> None:
    """`--signals q,cmd` on a cell's log (columns `left/q.j1`, `right/q.j1`) drew nothing."""
    cell = tmp_path / "cell.csv"
    cell.write_text("time_s,left/q.j1,right/q.j1,left/dq.j1,left/cmd.j1\r\n0.0,1,2,3,4\r\n0.002,1,2,3,4\r\n")
    assert plot_csv(cell, tmp_path / "a.png", ["q", "cmd"]).split(": ", 1)[1].startswith("3 plots")
    assert plot_csv(cell, tmp_path / "b.png", ["left/q"]).split(": ", 1)[1].startswith("1 plots")
