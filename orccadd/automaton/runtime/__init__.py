"""What the execution machine steps: `Runner` (one automaton, one reaction per instant, on the
highest-priority thread) and `NetworkRunner` (a network's automata).
"""
