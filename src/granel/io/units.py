"""Parsing of quantities written with units in scenario files and on the command line."""

from __future__ import annotations

import math
import re

_TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "µs": 1e-6, "ns": 1e-9}
_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"


def parse_time(value) -> float:
    """'0.8ms' -> 8e-4; '1us' -> 1e-6; 4e-8 -> 4e-8 (bare numbers are seconds)."""
    if isinstance(value, bool):
        raise ValueError(f"not a time: {value!r}")
    if isinstance(value, (int, float)):
        return float(value)
    m = re.fullmatch(rf"\s*({_NUM})\s*([a-zµ]*)\s*", str(value))
    if not m:
        raise ValueError(f"not a time: {value!r} (use e.g. 0.8ms, 1us, 4e-8)")
    unit = m.group(2) or "s"
    if unit not in _TIME_UNITS:
        raise ValueError(f"unknown time unit {unit!r} in {value!r} (use s, ms, us, ns)")
    return float(m.group(1)) * _TIME_UNITS[unit]


_WALL_UNITS = {"h": 3600.0, "min": 60.0, "m": 60.0, "s": 1.0}


def parse_wall_time(value: str) -> float:
    """A wall-time limit: '90s' -> 90.0, '30min' -> 1800.0, '2h' -> 7200.0 (bare numbers are
    seconds); ValueError unless positive and finite."""
    t = str(value).strip().lower()
    scale = 1.0
    for unit, factor in _WALL_UNITS.items():
        if t.endswith(unit):
            t, scale = t[: -len(unit)].strip(), factor
            break
    try:
        seconds = float(t) * scale
    except ValueError:
        seconds = float("nan")
    if not (math.isfinite(seconds) and seconds > 0):
        raise ValueError(f"{value!r}: give a positive wall time, e.g. 90s, 30min or 2h")
    return seconds


def wall_time_option(text: str | None, option: str) -> float | None:
    """An option's wall-time limit (`parse_wall_time`; None stays None), an InputError naming
    the option otherwise (exit 2)."""
    from ..guard.exits import InputError

    try:
        return None if text is None else parse_wall_time(text)
    except ValueError as e:
        raise InputError(f"{option} {e}") from None
