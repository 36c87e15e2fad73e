"""Checks shared by the configs and the console commands, with one wording for each kind of error."""

from __future__ import annotations

import argparse
from collections.abc import Callable, Collection
from typing import Any


def check_choice(field_name: str, value: Any, allowed: Collection) -> None:
    """Raise ``ValueError("`field`: expected one of [...], got value")`` unless ``value`` is allowed."""
    if value not in allowed:
        raise ValueError(f"`{field_name}`: expected one of {list(allowed)}, got {value!r}")


def check_positive_int(field_name: str, value: Any) -> None:
    """Raise ``ValueError("`field`: expected a positive integer, got value")`` unless an int >= 1."""
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ValueError(f"`{field_name}`: expected a positive integer, got {value!r}")


def int_at_least(minimum: int) -> Callable[[str], int]:
    """An argparse ``type`` accepting integers >= ``minimum``."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = None
        if value is None or value < minimum:
            raise argparse.ArgumentTypeError(f"expected an integer >= {minimum}, got {text!r}")
        return value

    return parse


positive_int = int_at_least(1)
"""An argparse ``type`` accepting integers >= 1."""
