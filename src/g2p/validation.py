"""Validation helpers for the frozen configuration dataclasses used across the core."""

from __future__ import annotations

import math
from collections.abc import Sequence


class ConfigError(ValueError):
    """A configuration value is invalid; the message names the field."""


def require(condition: bool, field: str, message: str) -> None:
    """Raise ConfigError naming `field` unless `condition` holds.

    Args:
        condition: what must be true.
        field: the configuration field's name, as the user writes it.
        message: what is wrong, including the offending value.
    """
    if not condition:
        raise ConfigError(f"{field}: {message}")


def require_positive(value: float, field: str) -> None:
    """Require a finite number > 0."""
    require(math.isfinite(value) and value > 0, field, f"must be a finite number > 0, got {value!r}")


def require_non_negative(value: float, field: str) -> None:
    """Require a finite number >= 0."""
    require(math.isfinite(value) and value >= 0, field, f"must be a finite number >= 0, got {value!r}")


def require_range(
    low: float, high: float, field: str, lower: float = -math.inf, upper: float = math.inf
) -> None:
    """Require a finite interval lower <= low < high <= upper."""
    require(
        math.isfinite(low) and math.isfinite(high) and lower <= low < high <= upper,
        field,
        f"must satisfy {lower} <= low < high <= {upper}, got ({low!r}, {high!r})",
    )


def require_length(values: Sequence[float], length: int, field: str) -> None:
    """Require exactly `length` finite numbers."""
    require(len(values) == length, field, f"must have {length} values, got {len(values)}")
    require(all(math.isfinite(v) for v in values), field, f"must be finite, got {list(values)!r}")
