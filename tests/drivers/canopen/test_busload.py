"""Bus load from a PDO layout: frame lengths, the issue's reference figures, the verdicts."""

from __future__ import annotations

import pytest

from orccadd.drivers.canopen.busload import Traffic, bus_load, frame_bits


def six_axes() -> list[Traffic]:
    return [Traffic("SYNC", 0), Traffic("RPDO", 8, per_cycle=6), Traffic("TPDO", 8, per_cycle=6)]


def test_frame_lengths() -> None:
    assert frame_bits(0) == (47, 55)
    assert frame_bits(8) == (111, 135)
    assert frame_bits(8, extended=True) == (131, 160)
    with pytest.raises(ValueError, match="0-8 data bytes"):
        frame_bits(9)


def test_six_axes_at_1_khz_and_500_hz() -> None:
    at_1k = bus_load(six_axes(), 0.001, 1_000_000)
    assert round(at_1k.load_min * 100) == 138 and round(at_1k.load_worst * 100) == 168
    at_500 = bus_load(six_axes(), 0.002, 1_000_000)
    assert round(at_500.load_min * 100) == 69 and round(at_500.load_worst * 100) == 84


def test_verdicts_and_the_suggested_period() -> None:
    kind, msg = bus_load(six_axes(), 0.001, 1_000_000).verdict()
    assert kind == "refuse"
    assert "above 90%" in msg and "shortest period that fits is 1.87 ms" in msg
    kind, msg = bus_load(six_axes(), 0.002, 1_000_000).verdict()
    assert kind == "warn" and "above 70%" in msg
    kind, _ = bus_load(six_axes(), 0.004, 1_000_000).verdict()
    assert kind == "ok"


def test_background_traffic_counts_whatever_the_period() -> None:
    hb = [Traffic("heartbeat", 1, rate_hz=10.0)] * 6
    load = bus_load(six_axes() + hb, 0.002, 1_000_000)
    assert load.bits_per_s_worst == pytest.approx(
        bus_load(six_axes(), 0.002, 1_000_000).bits_per_s_worst + 6 * 10 * 65
    )
    assert load.shortest_period_s() > bus_load(six_axes(), 0.002, 1_000_000).shortest_period_s()
