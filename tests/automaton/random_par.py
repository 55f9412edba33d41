"""Random missions with a `par` of independent branches, for the network's tests: each branch has
its own tasks (on its own resource), operator input and internal signal; the context around the
par preempts it, traps its exits, enters the safe procedure, or runs on after it."""

from __future__ import annotations

import random

CONTEXTS = [
    "handle\n  {par}\non fatal do\n  safe\nend",
    "await Go;\n{par};\nawait Stop",
    "trap T in\n  {par}\nend;\npresent Go then nothing else await Stop end",
    "do\n  {par}\nuntil Stop;\nawait Go",
    "weak do\n  {par}\nuntil Stop",
    "do\n  {par}\nuntil immediate Stop",
    "trap T in\n  par({par} || await Stop; exit T)\nend",
    "handle\n  await Go; {par}\non Stop do\n  nothing\non fatal do\n  safe\nend",
    "loop\n  await Go;\n  {par}\nend",
    "loop\n  do\n    {par}\n  until Stop;\n  pause\nend",
    "loop\n  do\n    {par};\n    await Go\n  until Stop\nend",
    "handle\n  loop\n    weak do {par} until Go;\n    pause\n  end\non fatal do\n  safe\nend",
]


# the safe procedure, sometimes running a branch's task again (its events are then the context's)
SAFE = ["await Stop", "A0_0; await Stop", "par(A0_1 || A1_1); await Stop"]


class _Gen:
    def __init__(self, rng: random.Random, b: int, traps: tuple[str, ...]) -> None:
        self.rng, self.b, self.traps = rng, b, traps
        self.tasks = [f"A{b}_{i}" for i in range(3)]
        self.n_traps = 0

    def stmt(self, depth: int) -> str:
        r, b = self.rng, self.b
        leaf = depth <= 0 or r.random() < 0.3
        if leaf:
            return r.choice(
                [r.choice(self.tasks), r.choice(self.tasks), f"await I{b}", "pause", f"emit S{b}", "nothing"]
                + [f"exit {t}" for t in self.traps]
                + (["safe"] if r.random() < 0.2 else [])
            )
        x, y = self.stmt(depth - 1), self.stmt(depth - 1)
        self.n_traps += 1
        u = f"U{b}_{self.n_traps}"
        return r.choice([
            f"{x}; {y}",
            f"{x}; {y}",
            f"present I{b} then {x} else {y} end",
            f"present S{b} then {x} else {y} end",
            f"do {x} until I{b}",
            f"weak do {x} until I{b}",
            f"do {x} until {r.choice(self.tasks)}.F",
            f"loop await I{b}; {x} end",
            f"suspend {x} when I{b}",
            f"trap {u} in par({x} || await I{b}; exit {u}) end",
            f"handle {x} on {r.choice(self.tasks)}.E do {y} end",
            f"{x}; emit S{b}",
        ])  # fmt: skip


def random_mission(seed: int, branches: int = 3, depth: int = 3) -> str:
    rng = random.Random(seed)
    context = rng.choice(CONTEXTS)
    safe = rng.choice(SAFE)
    traps = ("T",) if "trap T" in context else ()
    bodies = [_Gen(rng, b, traps).stmt(depth) for b in range(branches)]
    decls = []
    for b in range(branches):
        for i in range(3):
            decls.append(f"task A{b}_{i} on R{b}\n  post\n  T2 F\n  T3 E\nend")
    par = "par(" + " || ".join(bodies) + ")"
    resources = ", ".join(f"R{b}" for b in range(branches))
    inputs = ", ".join([*(f"I{b}" for b in range(branches)), "Go", "Stop"])
    signals = ", ".join(f"S{b}" for b in range(branches))
    main = "\n".join("  " + line for line in context.replace("{par}", par).splitlines())
    return (
        f"mission Random{seed}\nresource {resources}\ninput {inputs}\nsignal {signals}\n"
        + "\n".join(decls)
        + f"\nsafe procedure Rescue\n  {safe}\nend\nmain procedure Main\n{main}\nend\n"
    )
