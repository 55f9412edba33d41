"""`orccadctl`: the operator's command-line client (offline mission tools for now)."""
