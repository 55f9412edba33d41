"""The checks before anything moves: properties of the explicit automaton (or of a network
without its product), each failure with a counterexample; statement coverage; an interpreter
written apart from the compiler (the second route); abstract views for the reader.
"""
