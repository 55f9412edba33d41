"""A userspace virtual CAN bus for machines without SocketCAN (CI, containers, laptops): one hub
per bus speaking the socketcand protocol that python-can's stock `socketcand` interface uses
(`python -m orccadd.vcan --port 29536`, or the `orccadd-vcan` command). On a robot PC with
SocketCAN use the real bus, or `vcan0` (tools/setup_vcan.sh)."""
