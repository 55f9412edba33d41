from __future__ import annotations

from pathlib import Path

from tests.conftest import ROOT

MISSIONS = ROOT / "configs" / "missions"
KEEPSTABLE = MISSIONS / "keepstable.mission"
TEST_MISSIONS = Path(__file__).parent / "missions"
NO_GUARD = TEST_MISSIONS / "keepstable_no_guard.mission"
UNHANDLED_T3 = TEST_MISSIONS / "unhandled_t3.mission"


def two_branch_network(tail: str) -> str:
    """A mission whose `par` compiles as a network: thirty-four tasks on R0 in one branch, as many
    on R1 then `tail` in the other (inputs Stop, Go; signals X, O), `on fatal` entering the safe
    procedure; the par is at line 13."""
    tasks = "".join(f"task T{i} on R{i}\n  post\nend\n" for i in range(2))
    seq = ["; ".join(f"T{i}" for _ in range(34)) for i in range(2)]
    return (
        "mission N\nresource R0, R1\ninput Stop, Go\nsignal X, O\n" + tasks
        + f"main procedure P\n  handle\n    par({seq[0]} || {seq[1]}; {tail})\n"
        + "  on fatal do\n    safe\n  end\nend\nsafe procedure S\n  await Stop\nend\n"
    )  # fmt: skip
