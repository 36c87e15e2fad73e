"""Command lines of the real console tools (``omnid-record``, ``lerobot-train``, ``lerobot-eval``), checks of
what a finished one leaves behind, and a logged subprocess runner. Shared by the main job (``omnid-demo``,
:mod:`lerobot_omnid.benchmark.demo`) and the benchmark (``omnid-benchmark``,
:mod:`lerobot_omnid.benchmark.benchmark`).
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path

from gym_omnid import WORKSPACE_BOUNDS
from tqdm import tqdm

BIN = Path(sys.executable).parent
SIM_VOLUME_BOUNDS = json.dumps(WORKSPACE_BOUNDS, separators=(",", ":"))
"""``--policy.volume_bounds`` of the benchmark's OmniD runs: the envs' workspace, which holds every object."""
CHECKPOINT = Path("checkpoints") / "last" / "pretrained_model"
"""Where ``lerobot-train`` leaves the final checkpoint, relative to its ``--output_dir``."""
COMMIT_FILE = "commit.txt"
"""Beside an evaluation's ``eval_info.json`` (scripts under ``benchmarks/``): the code commit that ran it."""
Step = tuple[str, list[str], Path]
"""A resumable run of a script: its name (``<kind>/...``), its command line and the folder it writes."""


def json_list(items: Sequence[str]) -> str:
    """A list of strings as JSON, the form ``--policy.cameras`` parses with and without ``--policy.path``."""
    return json.dumps(list(items), separators=(",", ":"))


def env_cameras(cameras: Sequence[str]) -> str:
    return f"--env.cameras=[{','.join(cameras)}]"


def record_command(
    task: str,
    episodes: int,
    cameras: Sequence[str],
    image_size: int,
    root: Path,
    seed: int = 0,
    layout: str = "id",
    background: str = "id",
    static_calibration: bool = True,
) -> list[str]:
    """`omnid-record` of ``episodes`` expert episodes into ``root`` (repo id ``local/<root name>``).

    ``static_calibration`` (the benchmark's form) keeps each camera's calibration in its feature info
    (``--static-calibration``): OmniD then carries it in ``config.json``, where the benchmark's controls
    (``--policy.calibration_path``: blind, scrambled, perturbed) and ``omnid-robustness`` replace it; a
    calibration read from every frame would bypass them. False leaves ``omnid-record``'s default,
    per-frame calibration columns, for datasets to merge across rigs.
    """
    return [
        str(BIN / "omnid-record"),
        "--task",
        task,
        "--episodes",
        str(episodes),
        "--cameras",
        ",".join(cameras),
        "--image-size",
        str(image_size),
        "--layout",
        layout,
        "--background",
        background,
        "--seed",
        str(seed),
        "--root",
        str(root),
        "--repo-id",
        f"local/{root.name}",
        *(["--static-calibration"] if static_calibration else []),
    ]


def train_command(
    dataset_root: Path,
    output_dir: Path,
    policy_flags: Sequence[str],
    steps: int,
    batch_size: int,
    num_workers: int = 2,
    seed: int | None = None,
    log_freq: int = 25,
    extra: Sequence[str] = (),
) -> list[str]:
    """`lerobot-train` on a local dataset, saving one checkpoint at the end (``<output_dir>/`` + CHECKPOINT).

    ``policy_flags`` choose the policy: ``--policy.type=...`` to train from scratch or
    ``--policy.path=<checkpoint>`` to fine-tune, plus its options.
    """
    return [
        str(BIN / "lerobot-train"),
        f"--dataset.repo_id=local/{dataset_root.name}",
        f"--dataset.root={dataset_root}",
        "--dataset.video_backend=pyav",
        *policy_flags,
        f"--steps={steps}",
        f"--batch_size={batch_size}",
        f"--save_freq={steps}",
        f"--num_workers={num_workers}",
        f"--log_freq={log_freq}",
        *([f"--seed={seed}"] if seed is not None else []),
        f"--output_dir={output_dir}",
        "--wandb.enable=false",
        *extra,
    ]


def eval_command(
    checkpoint: Path,
    output_dir: Path,
    task: str,
    layout: str,
    cameras: Sequence[str],
    image_size: int,
    episodes: int,
    device: str,
    background: str = "id",
    seed: int | None = None,
    extra: Sequence[str] = (),
    batch_size: int = 1,
) -> list[str]:
    """`lerobot-eval` of a checkpoint in one setting of the omnid envs; ``seed`` is the first env seed.

    ``batch_size`` > 1 runs that many envs at once (LeRobot's vector env, one process each by default) and
    the policy on their batch; episode ``i`` still has env seed ``seed + i``."""
    return [
        str(BIN / "lerobot-eval"),
        f"--policy.path={checkpoint}",
        f"--policy.device={device}",
        "--env.type=omnid",
        f"--env.task={task}",
        f"--env.layout={layout}",
        f"--env.background={background}",
        env_cameras(cameras),
        f"--env.image_size={image_size}",
        f"--eval.n_episodes={episodes}",
        f"--eval.batch_size={batch_size}",
        *([f"--seed={seed}"] if seed is not None else []),
        f"--output_dir={output_dir}",
        *extra,
    ]


def control_calibration_command(checkpoint: Path, control: str, out: Path) -> list[str]:
    """Writes ``out``, the calibration file of OmniD's ``control`` (blind, scrambled) for ``checkpoint``
    (:mod:`lerobot_omnid.benchmark.control_calibration`)."""
    cmd = [sys.executable, "-m", "lerobot_omnid.benchmark.control_calibration"]
    return [*cmd, "--checkpoint", str(checkpoint), "--control", control, "--out", str(out)]


def recorded_episodes(root: Path) -> int:
    """Episodes in the dataset at ``root`` (0 when there is none)."""
    info = root / "meta" / "info.json"
    return json.loads(info.read_text()).get("total_episodes", 0) if info.is_file() else 0


def is_trained(output_dir: Path) -> bool:
    """Whether ``lerobot-train --output_dir=output_dir`` finished (its final checkpoint is saved)."""
    return (output_dir / CHECKPOINT / "model.safetensors").is_file()


def is_evaluated(output_dir: Path) -> bool:
    return (output_dir / "eval_info.json").is_file()


def run_logged(cmd: Sequence[str], log_path: Path, on_line: Callable[[str], object] | None = None) -> int:
    """Run ``cmd``, writing the command and its output (stdout and stderr) to ``log_path``; each line is
    also passed to ``on_line``. Returns the exit code."""
    log_path.parent.mkdir(parents=True, exist_ok=True)
    with (
        open(log_path, "w") as log,
        subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, bufsize=1) as proc,
    ):
        log.write(" ".join(cmd) + "\n")
        for line in proc.stdout:
            log.write(line)
            if on_line is not None:
                on_line(line)
    return proc.returncode


def run_stage(name: str, cmd: list[str], logs: Path) -> float:
    """Run one command, mirroring its output to the terminal and to ``logs/<name>.log``; seconds taken.
    Exits the program when the command fails."""
    start = time.perf_counter()
    returncode = run_logged(cmd, logs / f"{name}.log", on_line=sys.stdout.write)
    if returncode != 0:
        raise SystemExit(f"stage '{name}' failed (exit code {returncode}); see {logs / f'{name}.log'}")
    return time.perf_counter() - start


def run_steps(
    steps: Sequence[Step],
    out: Path,
    desc: str,
    is_done: Callable[[str, Path], bool],
    commit: str | None,
) -> None:
    """Run in order each step whose folder ``is_done(kind, folder)`` says is unfinished (kind: the name up to
    its first ``/``), under a progress bar; an unfinished folder is removed first, so a run is never resumed
    half-way. Each log goes to ``<out>/logs/``; an ``eval`` step's folder gets ``COMMIT_FILE``. Exits naming
    the step and its log when a command fails."""
    bar = tqdm(steps, desc=desc, unit="run")
    for name, cmd, target in bar:
        kind = name.split("/")[0]
        if is_done(kind, target):
            continue
        if target.exists():
            shutil.rmtree(target)
        bar.set_postfix_str(name)
        log = out / "logs" / f"{name.replace('/', '__')}.log"
        returncode = run_logged(cmd, log)
        if returncode != 0:
            raise SystemExit(f"{name} failed (exit code {returncode}); see {log}")
        if kind == "eval" and commit is not None:
            (target / COMMIT_FILE).write_text(commit + "\n")
