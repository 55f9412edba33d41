"""The mission language: its grammar and parser (text → syntax tree), the semantic checks
and expansion into kernel terms (`elaborate`), the kernel and its synchronous semantics, and
the checked `Program` the compiler takes.
"""
