"""Protocol layers under the hardware Physical Resources (CANopen CiA 402, ...)."""
