from __future__ import annotations

from pathlib import Path

from tests.conftest import ROOT

MISSIONS = ROOT / "configs" / "missions"
KEEPSTABLE = MISSIONS / "keepstable.mission"
TEST_MISSIONS = Path(__file__).parent / "missions"
NO_GUARD = TEST_MISSIONS / "keepstable_no_guard.mission"
UNHANDLED_T3 = TEST_MISSIONS / "unhandled_t3.mission"
