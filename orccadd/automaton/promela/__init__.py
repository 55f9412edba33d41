"""The Promela export: spin's exhaustive verifier cross-checks the checks' verdicts, on a model
written from the table and one written from the kernel terms, and both in lockstep.
"""
