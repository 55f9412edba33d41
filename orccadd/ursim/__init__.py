"""A simulated Universal Robots controller that stock clients (ur_rtde) connect to unmodified.

`python -m orccadd.ursim --config ROBOT.toml` serves, on 127.0.0.1, what a UR controller serves:
RTDE (protocol version 2) on 30004, the dashboard server on 29999 and the script ports
30001-30003, in front of the arm's dynamics (Pinocchio, from the robot config's URDF).

- `states`: robot mode, safety mode, runtime state, joint mode and status bits (RTDE guide);
- `fields`: RTDE field names and types, inputs and outputs;
- `arm`, `motion`: the arm behind the controller and the controller's own trajectory
  generation (servoj, speedj, movej, stopj) with its limits;
- `world`: a wall and a push on the tool, felt by the arm's dynamics (`ArmDynamics.external`);
- `ft_sensor`, `tool_contact`, `force_mode`, `task_frame`, `force_control`: the flange's
  force/torque sensor, tool_contact, force mode and freedrive (an admittance on the TCP);
- `speed_scaling`: the speed slider and the scaling of the planned motions;
- `controller`: the controller's cycle (500 Hz e-Series, 125 Hz CB3), safety, programs;
- `control_script`: our implementation of ur_rtde's control script (its register protocol);
- `rtde_server`, `dashboard`, `script_server`: the network side;
- `faults`: the control channel tests use to inject faults; `process`: start and stop the
  simulator from Python.
"""
