"""Simulated DYNAMIXEL X servos on a pseudo-terminal: the far end of a real chain, for tests.

`protocol` is Protocol 2.0 on the wire (CRC, stuffing, packets); `table` a servo's control
table and its access rules; `servo` a servo's instructions and faults, `loop` its control loops
and motor, `profile` its profile generator; `arm` the arm they move (Pinocchio); `chain` the
servos on one bus; `link` the pseudo-terminal and the wire time; `server` the loop; `control`
the fault-injection socket; `process` starts the simulator from tests.
"""
