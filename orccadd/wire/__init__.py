"""What crosses process boundaries: the telemetry layout and enums (`schema`), the command table
and request format (`commands`), and the shared-memory block (`telemetry`, the only part that
needs numpy). `schema` and `commands` are leaves: the standard library and `orccadd.types` only,
so `orccadctl` and the command daemon load neither a backend nor Pinocchio.
"""
