"""Strict loading of TOML into frozen dataclasses.

A field's metadata says what is allowed: `bounds=(lo, hi)` with `open_lo`/`open_hi`, `choices`,
`min_len`. Unknown keys, missing keys, wrong types and out-of-range values are refused with a
`ConfigError` naming the file, the key path, the value and what was allowed, e.g.
``configs/robots/ur5e.toml: joints[2].max_velocity_rad_s (=12.0) must be in (0, 3.2]``.
"""

from __future__ import annotations

import dataclasses
import math
import types
import typing
from collections.abc import Mapping
from typing import Any, TypeVar, Union, get_args, get_origin, get_type_hints

from orccadd.errors import ConfigError

T = TypeVar("T")


def field(
    *,
    default: Any = dataclasses.MISSING,
    bounds: tuple[float, float] | None = None,
    open_lo: bool = False,
    open_hi: bool = False,
    choices: tuple[Any, ...] | None = None,
    min_len: int | None = None,
    doc: str = "",
) -> Any:
    """A dataclass field with the constraints the strict loader checks."""
    meta = {
        "bounds": bounds,
        "open_lo": open_lo,
        "open_hi": open_hi,
        "choices": choices,
        "min_len": min_len,
        "doc": doc,
    }
    if isinstance(default, list | dict):
        raise TypeError("use an immutable default (tuple)")
    return dataclasses.field(default=default, metadata=meta)


def format_range(lo: float, hi: float, open_lo: bool, open_hi: bool) -> str:
    def num(v: float) -> str:
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return f"{v:g}"

    return f"{'(' if open_lo else '['}{num(lo)}, {num(hi)}{')' if open_hi else ']'}"


def check_bounds(file: str, key: str, value: float, meta: Mapping[str, Any]) -> None:
    bounds = meta.get("bounds")
    if bounds is None:
        return
    lo, hi = bounds
    open_lo, open_hi = meta.get("open_lo", False), meta.get("open_hi", False)
    ok_lo = value > lo if open_lo else value >= lo
    ok_hi = value < hi if open_hi else value <= hi
    if not (ok_lo and ok_hi) or math.isnan(value):
        raise ConfigError(file, key, f"(={value!r}) must be in {format_range(lo, hi, open_lo, open_hi)}")


def _type_name(tp: Any) -> str:
    origin = get_origin(tp)
    if origin is typing.Literal:
        return " or ".join(repr(a) for a in get_args(tp))
    if origin in (tuple,):
        args = get_args(tp)
        inner = _type_name(args[0]) if args else "value"
        return f"a list of {inner}"
    if dataclasses.is_dataclass(tp):
        return "a table"
    if origin in (Union, types.UnionType):
        return " or ".join(_type_name(a) for a in get_args(tp))
    if tp is type(None):
        return "absent"
    return {float: "a number", int: "an integer", str: "a string", bool: "true or false"}.get(
        tp, getattr(tp, "__name__", str(tp))
    )


def convert(tp: Any, value: Any, file: str, key: str, meta: Mapping[str, Any]) -> Any:
    """Convert one TOML value to `tp`, checking the metadata constraints."""
    origin = get_origin(tp)
    if origin in (Union, types.UnionType):
        args = [a for a in get_args(tp) if a is not type(None)]
        errors: list[ConfigError] = []
        for a in args:
            try:
                return convert(a, value, file, key, meta)
            except ConfigError as e:
                errors.append(e)
        if len(errors) == 1:
            raise errors[0]
        raise ConfigError(file, key, f"(={value!r}) must be {_type_name(tp)}")
    if origin is typing.Literal:
        allowed = get_args(tp)
        if value not in allowed:
            raise ConfigError(file, key, f"(={value!r}) must be one of {', '.join(repr(a) for a in allowed)}")
        return value
    if dataclasses.is_dataclass(tp):
        if not isinstance(value, Mapping):
            raise ConfigError(file, key, f"(={value!r}) must be a table")
        return load_dataclass(typing.cast(type[Any], tp), value, file, key)
    if origin is tuple:
        elem_types = get_args(tp)
        if not isinstance(value, list):
            raise ConfigError(file, key, f"(={value!r}) must be {_type_name(tp)}")
        min_len = meta.get("min_len")
        if min_len is not None and len(value) < min_len:
            raise ConfigError(file, key, f"has {len(value)} entries, at least {min_len} needed")
        elem = elem_types[0]
        inner_meta = {k: v for k, v in meta.items() if k != "min_len"}
        return tuple(convert(elem, v, file, f"{key}[{i}]", inner_meta) for i, v in enumerate(value))
    if origin is dict:
        _, vt = get_args(tp)
        if not isinstance(value, Mapping):
            raise ConfigError(file, key, f"(={value!r}) must be a table")
        return {str(k): convert(vt, v, file, f"{key}.{k}", meta) for k, v in value.items()}
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(file, key, f"(={value!r}) must be a number")
        check_bounds(file, key, float(value), meta)
        return float(value)
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(file, key, f"(={value!r}) must be an integer")
        check_bounds(file, key, value, meta)
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(file, key, f"(={value!r}) must be true or false")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(file, key, f"(={value!r}) must be a string")
        choices = meta.get("choices")
        if choices is not None and value not in choices:
            raise ConfigError(file, key, f"(={value!r}) must be one of {', '.join(repr(c) for c in choices)}")
        return value
    if tp is Any:
        return value
    raise TypeError(f"unsupported config type {tp!r} at {key}")


def load_dataclass(cls: type[T], data: Mapping[str, Any], file: str, prefix: str = "") -> T:
    """Build `cls` from a TOML table, refusing unknown and missing keys."""
    hints = get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}  # type: ignore[arg-type]

    def path(name: str) -> str:
        return f"{prefix}.{name}" if prefix else name

    unknown = [k for k in data if k not in fields]
    if unknown:
        allowed = ", ".join(sorted(fields))
        raise ConfigError(file, path(unknown[0]), f"is not a known key (allowed here: {allowed})")
    kwargs: dict[str, Any] = {}
    for name, f in fields.items():
        if name in data:
            kwargs[name] = convert(hints[name], data[name], file, path(name), f.metadata)
        elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            raise ConfigError(file, path(name), f"is missing ({_type_name(hints[name])} needed)")
    return cls(**kwargs)
