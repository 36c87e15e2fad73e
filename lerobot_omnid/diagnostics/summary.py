"""What the diagnostics' commands share: ``--out``, ``--report-only SUMMARY...`` (the report rebuilt from
committed summaries alone) and the one run-summary file each writes, with its command and commit."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from lerobot_omnid.measure.engine import portable_command
from lerobot_omnid.measure.report import write_markdown
from lerobot_omnid.measure.results import SUMMARY, RunSummary, read_run_summary, write_run_summary

ReportLines = Callable[[RunSummary], list[str]]
"""A diagnostic's report of one of its summaries, as markdown lines."""


def add_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument(
        "--report-only",
        nargs="+",
        type=Path,
        metavar="SUMMARY",
        help="run nothing: rebuild <out>/report.md from these summary.json files",
    )


def write_report(summaries: list[RunSummary], report_lines: ReportLines, out: Path) -> None:
    """``<out>/report.md``: the reports of ``summaries``, one after the other (printed too)."""
    lines: list[str] = []
    for summary in summaries:
        lines += ([""] if lines else []) + report_lines(summary)
    write_markdown(lines, out / "report.md")


def rebuild(
    parser: argparse.ArgumentParser, args: argparse.Namespace, protocol: str, report_lines: ReportLines
) -> bool:
    """With ``--report-only``: the report of those summaries (an error names the file); whether it ran."""
    if not args.report_only:
        return False
    try:
        summaries = [read_run_summary(path, protocol) for path in args.report_only]
    except ValueError as e:
        parser.error(f"--report-only: {e}")
    write_report(summaries, report_lines, args.out)
    return True


def finish(
    args: argparse.Namespace,
    protocol: str,
    module: str,
    argv: list[str] | None,
    settings: Mapping[str, Any],
    results: Mapping[str, Any],
    commit: str | None,
    report_lines: ReportLines,
) -> None:
    """``<out>/summary.json`` (with ``commit`` and the command: ``python -m module`` and its arguments, paths
    under the current folder relative to it) and ``<out>/report.md``."""
    command = portable_command(["python", "-m", module, *(sys.argv[1:] if argv is None else argv)])
    summary = RunSummary(protocol, settings, results=results, commit=commit, command=command)
    args.out.mkdir(parents=True, exist_ok=True)
    write_run_summary(args.out / SUMMARY, summary)
    write_report([summary], report_lines, args.out)
