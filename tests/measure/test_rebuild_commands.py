"""Every rebuild command of docs/results.md, docs/results/diagnostics.md and docs/results/validation.md, run
on the committed summaries alone: each section names one, and it must run (no checkpoint, no run folder)
and write its table.

The commands are run in this process, through the console scripts' and modules' own ``main`` functions, with
``--out`` pointed at a temporary folder; the page's ```` ```bash ```` blocks and inline report commands are
the commands, as a reader would paste them.
"""

from __future__ import annotations

import importlib
import re
import runpy
import shlex
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
RESULTS_PAGES = tuple(
    ROOT / "docs" / page for page in ("results.md", "results/diagnostics.md", "results/validation.md")
)
CONSOLE_SCRIPTS = {  # console script: module whose main(argv) it calls (pyproject.toml's [project.scripts])
    "omnid-benchmark": "lerobot_omnid.benchmark.benchmark",
    "omnid-robustness": "lerobot_omnid.benchmark.robustness",
    "omnid-demo": "lerobot_omnid.benchmark.demo",
}


def sections() -> dict[str, list[str]]:
    """The pages' ``##`` sections and the commands in each: its bash blocks (continuation lines joined)
    and its inline report commands (whole command lines, starting with the program)."""
    found: dict[str, list[str]] = {}
    text = "\n".join(page.read_text() for page in RESULTS_PAGES)
    for section in re.split(r"^## ", text, flags=re.MULTILINE)[1:]:
        title = section.splitlines()[0]
        blocks = re.findall(r"```bash\n(.*?)```", section, re.DOTALL)
        prose = re.sub(r"```.*?```", "", section, flags=re.DOTALL)
        inline = [
            span
            for span in re.findall(r"`([^`]+)`", prose)
            if "--report-only" in span and span.startswith(("omnid-", "python "))
        ]
        found[title] = [block.replace("\\\n", " ").strip() for block in blocks] + inline
    return found


def rebuild_commands() -> list[str]:
    return [cmd for commands in sections().values() for cmd in commands if "--report-only" in cmd]


def entry_point(argv: list[str]) -> tuple[Callable[[list[str]], object], list[str]]:
    """The function a command line runs and the arguments it gets."""
    program, *args = argv
    if program in CONSOLE_SCRIPTS:
        return importlib.import_module(CONSOLE_SCRIPTS[program]).main, args
    if program == "python" and args[0] == "-m":
        return importlib.import_module(args[1]).main, args[2:]
    if program == "python" and args[0].endswith(".py"):
        script = ROOT / args[0]

        def run_script(script_args: list[str]) -> None:
            sys.argv = [str(script), *script_args]
            runpy.run_path(str(script), run_name="__main__")

        return run_script, args[1:]
    raise AssertionError(f"{program}: not a command this test knows how to run in process")


def test_every_claim_has_one_rebuild_command():
    """Each claim's section names a --report-only command that rebuilds its table."""
    missing = [
        title for title, commands in sections().items() if not any("--report-only" in c for c in commands)
    ]
    assert missing == []


@pytest.mark.parametrize("command", rebuild_commands(), ids=lambda c: " ".join(shlex.split(c)[:3]))
def test_rebuild_command_runs_on_the_committed_summaries(command, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(ROOT)  # the page's summary paths are relative to the repository
    monkeypatch.setattr(sys, "argv", sys.argv[:])
    argv = shlex.split(command)
    if "--out" in argv:
        argv[argv.index("--out") + 1] = str(tmp_path / "out")
    main, args = entry_point(argv)
    module = sys.modules.get(getattr(main, "__module__", ""))
    if hasattr(module, "code_commit"):  # the report names the commit it was written at; git is a subprocess
        monkeypatch.setattr(module, "code_commit", lambda: "0" * 40)
    assert main(args) in (0, None)
    out = tmp_path / "out"
    if "--out" in argv:
        report = (out / "report.md").read_text()
        assert re.search(r"\d+/\d+|\d\.\d\d", report), report[:500]
    else:
        assert "ratio" in capsys.readouterr().out
