"""Checks shared by the configs and the console commands, with one wording for each kind of error, and the
options every protocol command shares."""

from __future__ import annotations

import argparse
from collections.abc import Callable, Collection
from pathlib import Path
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


def csv_of(
    kind: Callable[[str], Any], allowed: Collection | None, none: bool = False
) -> Callable[[str], tuple]:
    """argparse type: distinct comma-separated values of ``kind`` from ``allowed`` (any if None); ``none``
    also accepts the word none for the empty tuple."""

    def parse(text: str) -> tuple:
        if none and text.strip() == "none":
            return ()
        try:
            items = tuple(kind(x.strip()) for x in text.split(",") if x.strip())
        except ValueError:
            items = ()
        bad = [x for x in items if allowed is not None and x not in allowed]
        if not items or bad or len(set(items)) != len(items):
            expected = f"distinct values from {list(allowed)}" if allowed else "distinct values"
            raise argparse.ArgumentTypeError(f"expected comma-separated {expected}, got {text!r}")
        return items

    return parse


def add_protocol_options(parser: argparse.ArgumentParser) -> None:
    """``--dry-run``, ``--report-only`` and ``--summary``: what every protocol on the experiment engine
    offers besides running (see :func:`lerobot_omnid.measure.engine.report_from_summary`)."""
    parser.add_argument("--dry-run", action="store_true", help="print every planned command, run nothing")
    parser.add_argument("--report-only", action="store_true", help="run nothing; report what is done")
    parser.add_argument(
        "--summary",
        nargs="+",
        type=Path,
        help="with --report-only: rebuild <out>/report.md from this summary.json (several: the parts of one "
        "run, e.g. one task each, merged)",
    )
