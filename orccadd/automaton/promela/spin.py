"""Run spin's exhaustive safety verifier on a Promela model and read its verdict, check by check.

Both exports (`promela/export.py`, the table replay; `promela/structure.py`, the model built from the
program's structure) name each check's assertion `ok_<check>`: `ok_safety`, `ok_conflicts`,
`ok_prop<i>_<Name>` for the mission's `property` lines. pan runs with `-c0` (it does not stop at the
first error), so one run gives the verdict of every check in the model.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

from orccadd.errors import OrccaddError

# Settings used by `run_spin` (and printed in each model's header): a state space of a few hundred
# thousand states at most. Compiling pan.c (330 kB of pan's own code) is what takes the time: tcc
# where installed (0.04 s on this project's VM), else gcc at -O0 (0.3-1.7 s; three times faster
# than -O1). These state spaces are small: pan runs in hundredths of a second either way, with the
# same verdict and state counts.
SPIN_ARGS = ("-a",)
C_COMPILERS = ("tcc", "gcc", "cc")
CC_ARGS = ("-O0", "-DSAFETY", "-DVECTORSZ=4096")
PAN_ARGS = ("-m1000000", "-w20", "-c0", "-n")
SETTINGS = (
    f"spin {' '.join(SPIN_ARGS)} model.pml && tcc (else gcc) {' '.join(CC_ARGS)} -o pan pan.c && "
    f"./pan {' '.join(PAN_ARGS)}"
)


def c_compiler() -> str | None:
    """The first C compiler installed of `C_COMPILERS`."""
    return next(filter(None, map(shutil.which, C_COMPILERS)), None)


_VIOLATED = re.compile(r"assertion violated ok_(\w+)")


def check_name(ok_bit: str) -> str:
    """`safety` -> "safety", `prop2_NeverBoth` -> "property NeverBoth" (the verifier's check names)."""
    m = re.fullmatch(r"prop\d+_(\w+)", ok_bit)
    return f"property {m.group(1)}" if m else ok_bit


def prop_bit(index: int, name: str) -> str:
    """The assertion variable of the mission's property number `index` (names may repeat)."""
    return f"ok_prop{index}_{name}"


@dataclass(frozen=True)
class SpinVerdict:
    ok: bool
    errors: int
    states_stored: int
    output: str
    failed: frozenset[str] = field(default_factory=frozenset)  # the checks with a violated assertion
    invalid_ends: int = 0  # the model itself blocked outside an end state: a bug of the export

    def passed(self, check: str) -> bool:
        return check not in self.failed


def run_spin(model: str, timeout_s: float = 120.0) -> SpinVerdict:
    """Compile and run spin's exhaustive safety verifier on a model (needs spin and a C compiler)."""
    spin, cc = shutil.which("spin"), c_compiler()
    if spin is None or cc is None:
        raise OrccaddError("spin and a C compiler are needed (make setup installs them)")
    with tempfile.TemporaryDirectory(prefix="orccadd-spin-") as tmp:
        d = Path(tmp)
        (d / "model.pml").write_text(model)
        _run([spin, *SPIN_ARGS, "model.pml"], d, timeout_s)
        _run([cc, *CC_ARGS, "-o", "pan", "pan.c"], d, timeout_s)
        text = subprocess.run(
            ["./pan", *PAN_ARGS], cwd=d, capture_output=True, text=True, timeout=timeout_s
        ).stdout
    return parse_pan(text)


def _run(cmd: list[str], cwd: Path, timeout_s: float) -> None:
    proc = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=timeout_s)
    if proc.returncode != 0:
        raise OrccaddError(f"{' '.join(cmd)} failed: {proc.stdout[-1500:]} {proc.stderr[-1500:]}")


def parse_pan(text: str) -> SpinVerdict:
    m = re.search(r"errors: (\d+)", text)
    if m is None:
        raise OrccaddError(f"could not read spin's verdict:\n{text[-1000:]}")
    if "max search depth too small" in text:
        raise OrccaddError(f"spin's search was cut short (raise pan's -m):\n{text[-1000:]}")
    stored = re.search(r"(\d+) states, stored", text)
    errors = int(m.group(1))
    return SpinVerdict(
        ok=errors == 0,
        errors=errors,
        states_stored=int(stored.group(1)) if stored else 0,
        output=text,
        failed=frozenset(check_name(b) for b in _VIOLATED.findall(text)),
        invalid_ends=len(re.findall(r"pan:\d+: invalid end state", text)),
    )
