"""CANopen: the CiA 402 drive profile, object-dictionary capabilities, bus load, the bus itself."""
