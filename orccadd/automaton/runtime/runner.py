"""Steps a compiled automaton, one reaction per instant: the mission's runtime on the
highest-priority thread (the daemon drives a `NetworkRunner` through the same interface)."""

from __future__ import annotations

from orccadd.automaton.compiler.automaton import Automaton


class Runner:
    """Steps an automaton, one reaction per instant. Cheap enough for the highest-priority thread."""

    __slots__ = ("automaton", "relevant", "state", "table")

    def __init__(self, automaton: Automaton) -> None:
        self.automaton = automaton
        # a private plain-dict copy: the automaton's rows are read-only views, a lookup through one
        # costs about 50 ns more; each row also under every input set it stands for (a class's
        # other events: one lookup, no `normalize`); built once when the mission is loaded
        self.table = tuple(
            {x: hit for key, hit in row.items() for x in automaton.stands_for(key)} for row in automaton.table
        )
        self.relevant = automaton.relevant
        self.state = 0

    def react(self, inputs: int) -> int:
        """Inputs present in this instant → action bits. Never raises for inputs outside the model."""
        self.state, actions = self.peek(self.state, inputs)
        return actions

    def peek(self, state: int, inputs: int) -> tuple[int, int]:
        """The reaction of `state` to `inputs`, (next state, action bits), without taking it."""
        hit = self.table[state].get(inputs & self.relevant[state])
        if hit is None:
            hit = self.table[state][self.automaton.normalize(state, inputs)]
        return hit

    # the stepping interface the daemon drives a mission by, the same for a `NetworkRunner`
    # (whose states are snapshots): where it is, what the tasks there are, whether it waits
    def snapshot(self) -> int:
        return self.state

    def restore(self, state: int) -> None:
        self.state = state

    def active_in(self, state: int) -> tuple[int, ...]:
        """The Robot-Tasks active in `state` (task indices, a task once)."""
        return tuple(sorted(set(self.automaton.active[state])))

    def waits(self, state: int) -> bool:
        """`state` reacts to no input by staying as it is, doing nothing: it waits for one."""
        nxt = self.table[state].get(0)
        return nxt is None or (nxt[0] == state and nxt[1] == 0)

    def number(self, state: int) -> int:
        """The state as the trace records it."""
        return state
