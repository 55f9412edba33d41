"""The compiler: kernel terms → one explicit `Automaton` (every reachable state under every
input combination, constructive causality, a non-causal cycle named), or, for a `par` of
independent branches, a `Network` of automata.
"""
