#!/bin/sh
# Create and bring up a kernel virtual CAN interface (default vcan0) where the kernel has vcan.
# Tests use it when it exists and the userspace hub (python -m orccadd.vcan) otherwise;
# the two-bus rig (canopen-2bus) uses vcan0 and vcan1 when both exist: run it once for each.
# Needs root (or CAP_NET_ADMIN). Exit 0: the interface is up; 1: this kernel has no vcan.
set -eu
IFACE="${1:-vcan0}"
if [ -d "/sys/class/net/$IFACE" ]; then
  ip link set up "$IFACE"
  echo "$IFACE: already there, up"
  exit 0
fi
if ! modprobe vcan 2>/dev/null && ! grep -qw vcan /proc/modules 2>/dev/null; then
  echo "setup_vcan: this kernel has no vcan module (no SocketCAN?): use the userspace hub," \
       "python -m orccadd.vcan" >&2
  exit 1
fi
if ! ip link add dev "$IFACE" type vcan 2>/dev/null; then
  echo "setup_vcan: cannot create $IFACE (vcan unsupported or not permitted)" >&2
  exit 1
fi
ip link set up "$IFACE"
echo "$IFACE: created, up"
