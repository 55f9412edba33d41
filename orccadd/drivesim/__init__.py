"""Simulated CANopen CiA 402 drives: the far end of a real bus, for tests without hardware.

`slave` is a CANopen slave (NMT, SDO server, PDOs, SYNC, heartbeat, EMCY) over an object
dictionary read from an EDS/DCF; `axis` puts a CiA 402 drive behind it; `plant` is the arm
those drives move (one Pinocchio simulation, so joints are coupled); `server` is the process.
"""
