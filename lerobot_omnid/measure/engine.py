"""The experiment engine: every protocol is a list of runs (:class:`Run`), and this module plans, runs,
resumes and stamps them.

A run is one real console command (``omnid-record``, ``lerobot-train``, ``lerobot-eval``, ...) with the
folder or file it writes, the runs whose outputs it reads, and, for an evaluation, the table cell it fills.
Its *fingerprint* hashes its command line, the fingerprints of the runs it needs and the contents of the
files it reads that no run of the plan makes (a checkpoint trained elsewhere, a calibration file the
protocol writes), so it changes when anything upstream is asked for, or is, different. A run is done only
when its products exist *and* its stamp (``<out>/stamps/<name>.json``, written when the command succeeds)
carries the fingerprint asked for now: rerunning a campaign with other options reruns exactly the runs
they change, and everything downstream, and never reports results made for another plan.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import re
import shlex
import shutil
import subprocess
import sys
import time
from collections.abc import Callable, Collection, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from tqdm import tqdm

from lerobot_omnid.cli import add_protocol_options
from lerobot_omnid.measure.results import (
    SUMMARY,
    EvalEntry,
    EvalRecord,
    RunSummary,
    merge_run_summaries,
    read_run_summary,
    record_of,
    write_run_summary,
)

STAMPS = "stamps"
"""Folder of the stamps under a campaign's output folder."""
LOGS = "logs"
CHECKPOINT = Path("checkpoints") / "last" / "pretrained_model"
"""Where ``lerobot-train`` leaves its final model, inside its ``--output_dir``."""
PRODUCTS: dict[str, tuple[str, ...]] = {
    "record": ("meta/info.json",),
    "merge": ("meta/info.json",),
    "train": (str(CHECKPOINT / "model.safetensors"),),
    "prepare": ("config.json",),
    "eval": ("eval_info.json",),
    "offline": ("offline_eval.json",),
    "probe": ("summary.json",),
    "calibration": ("",),  # the output is the file itself
}
"""What each kind of run leaves in its output (paths relative to it) when it finished."""


@dataclass(frozen=True)
class Run:
    """One command of a plan.

    Attributes:
        name: unique in the plan; names its log and its stamp.
        kind: one of :data:`PRODUCTS`' keys: what the command makes.
        cmd: the command line, as a user would paste it.
        output: the folder (or, for "calibration", the file) the command writes.
        needs: names of the runs whose outputs this one reads (earlier in the plan).
        episodes: a "record" run's episodes.
        result: an evaluation's table cell (model, task, setting), with its eval ``seed``, the
            ``train_seed`` of its model, its ``control`` ("" for the checkpoint as trained) and its
            ``tags`` (what else tells the cell from the protocol's others: see ``results.tags_of``).
        inputs: files the command reads that no run of the plan makes.
        fingerprint, stamp: set by :func:`plan`.
    """

    name: str
    kind: str
    cmd: tuple[str, ...]
    output: Path
    needs: tuple[str, ...] = ()
    episodes: int = 0
    result: tuple[str, str, str] | None = None
    seed: int | None = None
    train_seed: int | None = None
    control: str = ""
    tags: tuple[tuple[str, str], ...] = ()
    inputs: tuple[Path, ...] = ()
    fingerprint: str = ""
    stamp: Path | None = None


WHOLE_FILE_BYTES = 8 << 20
"""Files up to this size are hashed whole; of larger ones (weights), the size and the first and last MiB."""


def file_fingerprint(path: Path) -> str:
    """A hash of a file's contents ("missing" when there is none); independent of its time stamps, so a
    copied checkpoint keeps its fingerprint."""
    if not path.is_file():
        return "missing"
    digest = hashlib.sha256()
    size = path.stat().st_size
    with open(path, "rb") as f:
        if size <= WHOLE_FILE_BYTES:
            digest.update(f.read())
        else:
            digest.update(str(size).encode())
            digest.update(f.read(1 << 20))
            f.seek(-(1 << 20), 2)
            digest.update(f.read())
    return digest.hexdigest()[:16]


def plan(runs: Sequence[Run], out: Path) -> list[Run]:
    """Check a protocol's runs (unique names, known kinds, needs listed before) and give each its
    fingerprint and stamp path under ``out``, the campaign's folder."""
    fingerprints: dict[str, str] = {}
    files: dict[Path, str] = {}
    planned = []
    for run in runs:
        if run.name in fingerprints:
            raise ValueError(f"plan: two runs are named {run.name!r}")
        if run.kind not in PRODUCTS:
            raise ValueError(f"plan: {run.name}: kind {run.kind!r} is not one of {sorted(PRODUCTS)}")
        unknown = [n for n in run.needs if n not in fingerprints]
        if unknown:
            raise ValueError(f"plan: {run.name} needs {unknown}, which are not planned before it")
        for path in run.inputs:
            if path not in files:  # each file hashed once per plan, however many runs read it
                files[path] = file_fingerprint(path)
        inputs = [files[path] for path in run.inputs]
        # Paths inside the campaign's folder count relative to it and the program by its name (any Python
        # as "python"): a moved or copied folder, or another checkout's, resumes.
        program = re.sub(r"^python[\d.]*$", "python", Path(run.cmd[0]).name)
        cmd = [program, *(arg.replace(str(out), "<out>") for arg in run.cmd[1:])]
        content = json.dumps([cmd, [fingerprints[n] for n in run.needs], inputs])
        fingerprints[run.name] = hashlib.sha256(content.encode()).hexdigest()[:16]
        stamp = out / STAMPS / f"{run.name}.json"
        planned.append(replace(run, fingerprint=fingerprints[run.name], stamp=stamp))
    return planned


def read_stamp(run: Run) -> dict[str, Any] | None:
    """What the stamp of ``run`` says (fingerprint, command, commit, seconds), or None without one."""
    if run.stamp is None or not run.stamp.is_file():
        return None
    return json.loads(run.stamp.read_text())


def has_products(run: Run) -> bool:
    return all((run.output / p if p else run.output).exists() for p in PRODUCTS[run.kind])


def state(run: Run) -> str:
    """ "done" (products there, made by this very command and inputs), "stale" (products there, made for
    another plan or before stamps existed) or "to run"."""
    if not has_products(run):
        return "to run"
    stamp = read_stamp(run)
    if stamp is not None and stamp.get("fingerprint") == run.fingerprint and run.fingerprint:
        return "done"
    return "stale"


def is_done(run: Run) -> bool:
    return state(run) == "done"


def schedule(runs: Sequence[Run], recorded: Collection[str] = ()) -> list[Run]:
    """The runs still to run, in the order to run them: every run that is not done and whose result is not
    ``recorded`` (fingerprints of results kept in an earlier campaign's run summary), each preceded by
    those of its needs not done yet, so that a dataset or a model is made just before its first use. A run
    whose consumers are all done or recorded is not run: a campaign resumed in a fresh folder from its
    committed summary trains only the models whose evaluations are missing."""
    by_name = {run.name: run for run in runs}
    consumed = {name for run in runs for name in run.needs}
    order: list[Run] = []
    seen: set[str] = set()

    def visit(run: Run) -> None:
        if run.name in seen:
            return
        seen.add(run.name)
        for name in run.needs:
            if not is_done(by_name[name]):
                visit(by_name[name])
        order.append(run)

    for run in runs:
        if run.name not in consumed and not is_done(run) and run.fingerprint not in recorded:
            visit(run)
    return order


def portable_command(cmd: Sequence[str]) -> tuple[str, ...]:
    """``cmd`` with the paths under the current folder made relative to it, as a run summary records it (a
    committed summary names no folder of one machine)."""
    here = str(Path.cwd()) + "/"
    return tuple(arg.replace(here, "") for arg in cmd)


def describe_plan(runs: Sequence[Run], recorded: Collection[str] = ()) -> list[str]:
    """Every run with its state and its command line (``--dry-run``); a run not done whose result is
    ``recorded`` (see :func:`schedule`) shows as such."""
    to_run = {run.name for run in schedule(runs, recorded)}
    lines = []
    for i, run in enumerate(runs, 1):
        now = state(run) if run.name in to_run or is_done(run) else _idle_state(run, recorded)
        lines += [f"[{i}/{len(runs)}] {run.name} ({now})", "  " + shlex.join(run.cmd)]
    return lines


def _idle_state(run: Run, recorded: Collection[str]) -> str:
    """Why :func:`schedule` leaves ``run`` out: "reused" (done), "recorded" (its result is kept elsewhere) or
    "not needed" (only done or recorded runs need it)."""
    if is_done(run):
        return "reused"
    return "recorded" if run.fingerprint in recorded else "not needed"


def code_commit() -> str | None:
    """The git commit of this package's checkout, ``+dirty`` when tracked files differ from it; None when
    it is not a git checkout (an installed copy)."""
    root = Path(__file__).resolve().parents[2]

    def git(*args: str) -> str:
        return subprocess.run(
            ["git", *args], cwd=root, capture_output=True, text=True, check=True
        ).stdout.strip()

    try:
        commit = git("rev-parse", "HEAD")
        dirty = git("status", "--porcelain", "--untracked-files=no")
    except (OSError, subprocess.CalledProcessError):
        return None
    return commit + ("+dirty" if dirty else "")


def run_logged(cmd: Sequence[str], log_path: Path, on_line: Callable[[str], object] | None = None) -> int:
    """Run ``cmd``, writing the command and its output (stdout and stderr) to ``log_path``; each line is
    also passed to ``on_line``. Returns the exit code."""
    log_path.parent.mkdir(parents=True, exist_ok=True)
    with (
        open(log_path, "w") as log,
        subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, bufsize=1) as proc,
    ):
        log.write(shlex.join(cmd) + "\n")
        for line in proc.stdout:
            log.write(line)
            if on_line is not None:
                on_line(line)
    return proc.returncode


def clear_output(run: Run, out: Path) -> None:
    """Remove what an interrupted or stale run left (the tools refuse an existing dataset or training
    folder, and a stale evaluation's files must not survive into the new one); only inside ``out``."""
    if run.stamp is not None:
        run.stamp.unlink(missing_ok=True)
    if not run.output.exists():
        return
    run.output.resolve().relative_to(out.resolve())  # never delete outside the campaign's folder
    tqdm.write(f"{run.name}: removing {run.output} ({'stale' if has_products(run) else 'incomplete'})")
    if run.output.is_dir():
        shutil.rmtree(run.output)
    else:
        run.output.unlink()


def execute(
    runs: Sequence[Run],
    out: Path,
    verbose: bool = False,
    commit: str | None = None,
    desc: str = "runs",
    on_done: Callable[[Run], object] | None = None,
    stop_on_failure: bool = False,
    recorded: Collection[str] = (),
) -> tuple[dict[str, str], dict[str, float]]:
    """Run the runs :func:`schedule` gives, in its order; a failed run blocks the runs that need its output.

    A run that succeeds gets its stamp (fingerprint, command, ``commit``, seconds), then ``on_done(run)``
    (e.g. a protocol's run summary). ``stop_on_failure`` exits at the first failure, naming its log.
    Returns each run's status ("reused": done before; "recorded": its result is in ``recorded``; "not
    needed": only done or recorded runs need it; "ran", "failed", "blocked") and the seconds of those run.
    """
    to_run = schedule(runs, recorded)
    status = {run.name: _idle_state(run, recorded) for run in runs}
    seconds: dict[str, float] = {}
    bar = tqdm(to_run, desc=desc, unit="run", file=sys.stdout, dynamic_ncols=True)
    for run in bar:
        bar.set_postfix_str(run.name)
        blocked = [n for n in run.needs if status.get(n) in ("failed", "blocked")]
        if blocked:
            status[run.name] = "blocked"
            tqdm.write(f"{run.name}: skipped, it needs {', '.join(blocked)}")
            continue
        clear_output(run, out)
        log = out / LOGS / f"{run.name.replace('/', '__')}.log"
        last = [0.0]

        def show(line: str, run: Run = run, last: list[float] = last) -> None:
            if verbose:
                tqdm.write(line.rstrip())
            elif time.monotonic() - last[0] > 1.0 and line.strip():
                last[0] = time.monotonic()
                bar.set_postfix_str(f"{run.name}: {line.strip()[-60:]}")

        start = time.perf_counter()
        returncode = run_logged(run.cmd, log, on_line=show)
        seconds[run.name] = time.perf_counter() - start
        if returncode == 0 and has_products(run):
            write_stamp(run, commit, seconds[run.name])
            status[run.name] = "ran"
            if on_done is not None:
                on_done(run)
            tqdm.write(f"{run.name}: done in {seconds[run.name]:.0f} s")
            continue
        status[run.name] = "failed"
        message = f"{run.name}: FAILED (exit code {returncode}, output incomplete); log: {log}"
        if stop_on_failure:
            raise SystemExit(message)
        tqdm.write(message)
    return status, seconds


def run_protocol(
    runs: Sequence[Run],
    out: Path,
    desc: str,
    write_outputs: Callable[[], object],
    dry_run: bool = False,
    report_only: bool = False,
) -> None:
    """What a protocol command does with its plan: ``dry_run`` prints it; otherwise it runs what is not
    done (unless ``report_only``; stopping at the first failure) with ``write_outputs()`` (its summary and
    report) after each finished run, and once more at the end."""
    if dry_run:
        print("\n".join(describe_plan(runs)))
        return
    if not report_only:
        execute(
            runs,
            out,
            commit=code_commit(),
            desc=desc,
            on_done=lambda _: write_outputs(),
            stop_on_failure=True,
        )
    write_outputs()


def eval_entry(run: Run) -> EvalEntry:
    """An evaluation run as the cell it fills, with the commit of its stamp."""
    if run.kind != "eval" or run.result is None:
        raise ValueError(
            f"{run.name}: expected an evaluation run with its table cell (result), got kind {run.kind!r} "
            f"and result {run.result!r}"
        )
    return EvalEntry(
        run.result,
        run.seed,
        run.output / "eval_info.json",
        run.train_seed,
        run.control,
        portable_command(run.cmd),
        stamp_commit(run),
        run.fingerprint,
        run.tags,
    )


def evaluations(runs: Sequence[Run]) -> list[EvalRecord]:
    """The records of the evaluations of ``runs`` that are done, in plan order: each its cell's counts
    (from its ``eval_info.json``), seeds, control, tags, command, commit and fingerprint."""
    return [record_of(eval_entry(r)) for r in runs if r.kind == "eval" and is_done(r)]


def write_stamp(run: Run, commit: str | None, seconds: float) -> None:
    if run.stamp is None:
        raise RuntimeError(f"{run.name}: not planned (engine.plan gives runs their stamps)")
    run.stamp.parent.mkdir(parents=True, exist_ok=True)
    stamp = {
        "name": run.name,
        "fingerprint": run.fingerprint,
        "command": shlex.join(run.cmd),
        "commit": commit,
        "seconds": round(seconds, 1),
    }
    run.stamp.write_text(json.dumps(stamp, indent=2) + "\n")


def stamp_commit(run: Run) -> str | None:
    """The commit the code had when ``run`` was made (its stamp's), or None."""
    stamp = read_stamp(run)
    return stamp.get("commit") if stamp else None


def report_from_summary(
    parser: argparse.ArgumentParser,
    args: argparse.Namespace,
    out: Path,
    protocol: str,
    write_report: Callable[[RunSummary, Path], object],
) -> bool:
    """With ``--summary``: ``write_report(summary, <out>/report.md)`` from those run summaries of
    ``protocol`` alone (committed ones; no run folder needed; several: parts of one protocol run, e.g. one
    task each, merged), and True; without it, False. ``--summary`` needs ``--report-only``."""
    if not args.summary:
        return False
    if not args.report_only:
        parser.error("--summary: expected with --report-only, got it without")
    try:
        parts = [read_run_summary(path, protocol) for path in args.summary]
        summary = merge_run_summaries(parts, [str(path) for path in args.summary])
    except ValueError as e:
        parser.error(f"--summary: {e}")
    write_report(summary, out / "report.md")
    return True


def protocol_main(
    parser: argparse.ArgumentParser,
    argv: Sequence[str] | None,
    protocol: str,
    make_plan: Callable[[argparse.Namespace, Path], Sequence[Run]],
    summarise: Callable[[Sequence[Run], str | None], RunSummary],
    write_report: Callable[[RunSummary, Path], object],
    results_dir: Callable[[Path], Path] = lambda out: out,
    after_summary: Callable[[RunSummary, Path], object] | None = None,
) -> int:
    """A protocol's command. ``parser`` (its ``--out`` and own options) gets the engine's; with
    ``--summary`` it reports committed summaries (:func:`report_from_summary`); otherwise the plan
    ``make_plan(args, out)`` goes to :func:`run_protocol`, which writes ``summarise(runs, commit)`` as
    ``summary.json`` into ``results_dir(out)``, then ``after_summary(summary, folder)`` (what a protocol
    decides from it, e.g. a selection file) and ``report.md``, after each finished run."""
    add_protocol_options(parser)
    args = parser.parse_args(argv)
    out = args.out.resolve()
    if report_from_summary(parser, args, out, protocol, write_report):
        return 0
    runs = make_plan(args, out)
    commit = code_commit()
    folder = results_dir(out)

    def write_outputs() -> None:
        summary = summarise(runs, commit)
        folder.mkdir(parents=True, exist_ok=True)
        write_run_summary(folder / SUMMARY, summary)
        if after_summary is not None:
            after_summary(summary, folder)
        write_report(summary, folder / "report.md")

    run_protocol(runs, out, protocol, write_outputs, args.dry_run, args.report_only)
    return 0
