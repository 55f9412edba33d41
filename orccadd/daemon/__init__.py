"""The real-time process of orccadd: control thread, automaton thread, telemetry."""
