"""What a value read from a file's JSON meta may be: predicates for the validators of datasets and path files, so a
bool never passes for a number and NaN never for a finite one."""

from __future__ import annotations

import math


def number(value, low: float = -math.inf, high: float = math.inf) -> bool:
    """Whether ``value`` is a number (not a bool, not NaN) from ``low`` to ``high``."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and low <= value <= high


def finite(value, low: float = -math.inf, high: float = math.inf) -> bool:
    """Whether ``value`` is a finite :func:`number` from ``low`` to ``high``."""
    return number(value, low, high) and math.isfinite(value)


def whole(value, low: int = 0, high: float = math.inf) -> bool:
    """Whether ``value`` is a whole number (not a bool) from ``low`` to ``high``."""
    return isinstance(value, int) and number(value, low, high)


def numbers(values, count: int | None) -> bool:
    """Whether ``values`` is a list of ``count`` (any number when None) finite numbers."""
    return isinstance(values, list) and count in (None, len(values)) and all(finite(v) for v in values)


def text(value) -> bool:
    return isinstance(value, str)


def texts(value) -> bool:
    """Whether ``value`` is a list of strings."""
    return isinstance(value, list) and all(isinstance(v, str) for v in value)
