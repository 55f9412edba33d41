"""DYNAMIXEL X servos over Protocol 2.0, on ROBOTIS's `dynamixel_sdk` (the `dynamixel` backend).

`models` the servo models (model number, torque constant, current unit, modes); `table` the
control-table items this backend uses; `units` joint units from and to servo units; `wire` the
packet lengths and their time on the line; `errors` hardware error bits and status errors by
name; `settings` the strict `[resource.settings]` loader; `port` the SDK's port with blocking
reads and the USB latency-timer check; `chain` the bus transactions (ping, reboot, item
reads/writes, the cyclic fast sync read and sync write); `startup` what configure and enable
write; `ramp` the safe stop's deceleration.
"""
