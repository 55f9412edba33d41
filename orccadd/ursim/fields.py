"""RTDE data types and recipes: how a list of field names becomes bytes on the wire.

The type names are the RTDE guide's (BOOL, UINT8, UINT32, UINT64, INT32, DOUBLE, VECTOR3D,
VECTOR6D, VECTOR6INT32, VECTOR6UINT32), big-endian like the rest of the protocol. A setup
request is answered with one type name per field, NOT_FOUND for a name the controller does not
have and IN_USE for an input another client already writes (RTDE guide, "Control package setup
outputs/inputs").
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Sequence
from enum import Enum
from typing import Any

NOT_FOUND = "NOT_FOUND"
IN_USE = "IN_USE"


class RtdeType(Enum):
    """An RTDE data type: its struct code and how many values it carries."""

    BOOL = ("?", 1)
    UINT8 = ("B", 1)
    UINT32 = ("I", 1)
    UINT64 = ("Q", 1)
    INT32 = ("i", 1)
    DOUBLE = ("d", 1)
    VECTOR3D = ("d", 3)
    VECTOR6D = ("d", 6)
    VECTOR6INT32 = ("i", 6)
    VECTOR6UINT32 = ("I", 6)

    def __init__(self, code: str, count: int) -> None:
        self.code = code
        self.count = count

    @property
    def fmt(self) -> str:
        return f"{self.count}{self.code}" if self.count > 1 else self.code


Getter = Callable[[], Any]  # a scalar, or a sequence of `count` values
Setter = Callable[[Any], None]


class OutputRecipe:
    """The fields one client reads, packed in its order at each package it is sent."""

    def __init__(
        self, names: Sequence[str], types: Sequence[RtdeType], getters: Sequence[Getter], frequency_hz: float
    ) -> None:
        self.names = tuple(names)
        self.types = tuple(types)
        self.frequency_hz = frequency_hz
        self._getters = tuple(zip(getters, (t.count > 1 for t in types), strict=True))
        self._struct = struct.Struct(">" + "".join(t.fmt for t in types))

    def pack(self) -> bytes:
        """The current values, packed (called by the controller's cycle)."""
        values: list[Any] = []
        for get, vector in self._getters:
            if vector:
                values.extend(get())
            else:
                values.append(get())
        return self._struct.pack(*values)


class InputRecipe:
    """The fields one client writes with a data package of this recipe's id."""

    def __init__(
        self, recipe_id: int, names: Sequence[str], types: Sequence[RtdeType], setters: Sequence[Setter]
    ) -> None:
        self.recipe_id = recipe_id
        self.names = tuple(names)
        self.types = tuple(types)
        self.setters = tuple(setters)
        self._struct = struct.Struct(">" + "".join(t.fmt for t in types))

    @property
    def size(self) -> int:
        return self._struct.size

    def unpack(self, payload: bytes) -> list[Any]:
        """One value per field (a tuple for a vector); `struct.error` if the size is wrong."""
        flat = self._struct.unpack(payload)
        out: list[Any] = []
        i = 0
        for t in self.types:
            out.append(flat[i] if t.count == 1 else flat[i : i + t.count])
            i += t.count
        return out

    def apply(self, values: Sequence[Any]) -> None:
        """Write the unpacked values into the controller (under the controller's lock)."""
        for set_value, v in zip(self.setters, values, strict=True):
            set_value(v)
