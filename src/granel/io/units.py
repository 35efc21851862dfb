"""Parsing of quantities written with units in scenario files and on the command line."""

from __future__ import annotations

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
