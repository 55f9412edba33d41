"""The layout of the commands that ask a UR controller for one of its own behaviours, shared by
the modules that write them (`orccadd.modules.ur`) and the resource that sends them
(`orccadd.physres.ur_rtde`). Element 0 of each is the tick that wrote it."""

from __future__ import annotations

FORCE_MODE = "force_mode"  # the command's name (the resource's input, the module's output)
FORCE_MODE_SIZE = 26  # tick time, task frame (6), selection (6), wrench (6), type, limits (6)
FORCE_MODE_UNIT = "ur.force_mode"
FREEDRIVE = "freedrive"
FREEDRIVE_SIZE = 13  # tick time, free axes (6), feature (6)
FREEDRIVE_UNIT = "ur.freedrive"
TOOL = "tool"
TOOL_SIZE = 11  # tick time, payload kg, payload centre of gravity (3, flange frame), TCP pose (6)
TOOL_UNIT = "ur.tool"
