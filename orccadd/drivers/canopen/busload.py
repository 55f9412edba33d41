"""CAN bus load from a PDO layout, a period and a bitrate (classical CAN, ISO 11898-1).

A data frame with an 11-bit identifier and n data bytes is 47 + 8n bits: SOF, identifier, RTR,
IDE, r0, DLC, data, CRC (1+11+1+1+1+4+8n+15 = 34+8n bits, the part that is bit-stuffed), CRC
delimiter, ACK slot and delimiter, EOF, intermission (1+2+7+3). With a 29-bit identifier the
stuffed part is 54+8n bits and the frame 67+8n. The transmitter inserts a stuff bit after
five equal bits; at worst (alternating runs) that is one per four bits after the first,
floor((stuffed - 1) / 4). A load is given as a range: no stuffing .. worst-case stuffing;
decisions use the worst case.

Six axes at 1 kHz with SYNC (0 bytes) + one 8-byte RPDO + one 8-byte TPDO each need
1,379-1,675 kbit/s: 138-168 % of a 1 Mbit/s bus; at 500 Hz 69-84 %.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

WARN_LOAD = 0.70
MAX_LOAD = 0.90


def frame_bits(payload_bytes: int, extended: bool = False) -> tuple[int, int]:
    """(bits without stuffing, bits with worst-case stuffing) of one data frame."""
    if not 0 <= payload_bytes <= 8:
        raise ValueError(f"a classical CAN frame carries 0-8 data bytes, not {payload_bytes}")
    stuffed = (54 if extended else 34) + 8 * payload_bytes
    base = (67 if extended else 47) + 8 * payload_bytes
    return base, base + (stuffed - 1) // 4


@dataclass(frozen=True)
class Traffic:
    """Frames on the bus: `per_cycle` frames of `payload_bytes` each control period, or, when
    `rate_hz` is set, that many frames per second whatever the period (heartbeats)."""

    name: str
    payload_bytes: int
    per_cycle: int = 1
    rate_hz: float = 0.0


@dataclass(frozen=True)
class BusLoad:
    period_s: float
    bitrate_bit_s: int
    bits_per_s_min: float
    bits_per_s_worst: float
    cyclic_bits_worst: int  # per control period
    background_bits_s_worst: float

    @property
    def load_min(self) -> float:
        return self.bits_per_s_min / self.bitrate_bit_s

    @property
    def load_worst(self) -> float:
        return self.bits_per_s_worst / self.bitrate_bit_s

    def shortest_period_s(self, max_load: float = MAX_LOAD) -> float:
        """The shortest control period at which the worst case stays within `max_load`."""
        room = max_load * self.bitrate_bit_s - self.background_bits_s_worst
        return math.inf if room <= 0 else self.cyclic_bits_worst / room

    def describe(self) -> str:
        return (
            f"bus load {self.load_min:.0%}-{self.load_worst:.0%} of {self.bitrate_bit_s / 1e6:g} Mbit/s "
            f"at {1 / self.period_s:g} Hz (no stuffing - worst-case stuffing)"
        )

    def verdict(self, warn_load: float = WARN_LOAD) -> tuple[str, str]:
        """("ok" | "warn" | "refuse", message); "warn" above `warn_load` (worst case)."""
        if self.load_worst > MAX_LOAD:
            p = self.shortest_period_s()
            hint = (
                f"; the shortest period that fits is {math.ceil(p * 1e5) / 1e2:g} ms "
                f"({1 / p:.0f} Hz or less), or raise the bitrate or map fewer bytes"
                if math.isfinite(p)
                else "; even without cyclic traffic the bus is full"
            )
            return "refuse", f"{self.describe()}: above {MAX_LOAD:.0%}{hint}"
        if self.load_worst > warn_load:
            return "warn", (
                f"{self.describe()}: above {warn_load:.0%}, little room for SDO and EMCY traffic "
                "(bus_load_warn in [resource.settings] accepts more)"
            )
        return "ok", self.describe()


def bus_load(traffic: list[Traffic], period_s: float, bitrate_bit_s: int) -> BusLoad:
    cyc_min = cyc_worst = 0
    bg_min = bg_worst = 0.0
    for t in traffic:
        lo, hi = frame_bits(t.payload_bytes)
        if t.rate_hz:
            bg_min += lo * t.rate_hz
            bg_worst += hi * t.rate_hz
        else:
            cyc_min += lo * t.per_cycle
            cyc_worst += hi * t.per_cycle
    return BusLoad(
        period_s=period_s,
        bitrate_bit_s=bitrate_bit_s,
        bits_per_s_min=cyc_min / period_s + bg_min,
        bits_per_s_worst=cyc_worst / period_s + bg_worst,
        cyclic_bits_worst=cyc_worst,
        background_bits_s_worst=bg_worst,
    )
