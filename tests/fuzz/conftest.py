"""Hypothesis settings of the fuzz suite, applied with `@fuzz(...)` (not loaded globally, so the
other suites' hypothesis tests keep their own).

Profile `fuzz` (the default; `make test`): bounded example counts, so the whole of tests/fuzz
runs in well under a minute on the project's 2-core VM; no deadline (the VM is noisy: inputs are
bounded instead). Not derandomized: each run explores new inputs from a fresh seed, printed at
the end of the run; replay it with `ORCCADD_FUZZ_SEED=N`. Failing examples are kept in
`.hypothesis/` and replayed first on the next run. `ORCCADD_FUZZ_PROFILE=fuzz-long` multiplies
the counts by 20; `benchmarks/fuzz.py --minutes N` runs for a set time.
"""

from __future__ import annotations

import os
import random
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import pytest
from hypothesis import HealthCheck, Phase, seed, settings
from hypothesis.database import DirectoryBasedExampleDatabase

from tests.conftest import ROOT

F = TypeVar("F", bound=Callable[..., Any])

SUPPRESSED = [
    HealthCheck.too_slow,
    HealthCheck.data_too_large,
    HealthCheck.large_base_example,
    HealthCheck.function_scoped_fixture,
]
settings.register_profile(
    "fuzz",
    deadline=None,
    derandomize=False,
    print_blob=True,
    report_multiple_bugs=False,  # shrink one failure, not each: a failing run stays short
    database=DirectoryBasedExampleDatabase(str(ROOT / ".hypothesis" / "examples")),
    suppress_health_check=SUPPRESSED,
)
settings.register_profile("fuzz-long", parent=settings.get_profile("fuzz"))
PROFILE = os.environ.get("ORCCADD_FUZZ_PROFILE", "fuzz")
SCALE = 20 if PROFILE == "fuzz-long" else 1
SEED = int(os.environ.get("ORCCADD_FUZZ_SEED") or random.SystemRandom().randrange(2**32))


def fuzz(max_examples: int, shrink: bool = True) -> Callable[[F], F]:
    """The suite's settings and seed for one `@given` test, with its bounded example count.
    `shrink=False` where one example is slow and readable as it is (a whole config file)."""
    phases = tuple(p for p in Phase if shrink or p not in (Phase.shrink, Phase.explain))

    def apply(test: F) -> F:
        s = settings(settings.get_profile(PROFILE), max_examples=max_examples * SCALE, phases=phases)
        out: F = seed(SEED)(s(test))
        return out

    return apply


def pytest_terminal_summary(terminalreporter: Any) -> None:
    terminalreporter.write_line(
        f"fuzz: hypothesis seed {SEED}, profile {PROFILE} (replay: ORCCADD_FUZZ_SEED={SEED})"
    )


@pytest.fixture(scope="session")
def fuzz_seed() -> int:
    return SEED


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The long profile runs 20 times the examples: 20 times the per-test timeout too."""
    if SCALE == 1:
        return
    here = Path(__file__).parent
    for item in items:
        if here in Path(str(item.path)).parents:
            item.add_marker(pytest.mark.timeout(120 * SCALE))
