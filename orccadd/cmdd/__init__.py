"""The companion command daemon: orccadctl's counterpart, a separate process from the real-time one."""
