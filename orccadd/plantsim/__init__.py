"""The simulated arm's own process (`python -m orccadd.plantsim`), started by the `sim_process`
resource: a `SimulatedArm` stepped on the wall clock, talking over a shared-memory channel.
A simulator beside the others (`drivesim`), not part of the resource layer."""
