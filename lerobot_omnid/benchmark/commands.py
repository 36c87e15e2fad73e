"""Command lines of the real console tools (``omnid-record``, ``lerobot-train``, ``lerobot-eval``) that every
protocol plans (the benchmark, robustness, the main job, readout selection, rigs and wrist); the engine
(:mod:`lerobot_omnid.measure.engine`) runs them."""

from __future__ import annotations

import json
import sys
from collections.abc import Sequence
from pathlib import Path

from gym_omnid import WORKSPACE_BOUNDS

BIN = Path(sys.executable).parent
SIM_VOLUME_BOUNDS = json.dumps(WORKSPACE_BOUNDS, separators=(",", ":"))
"""``--policy.volume_bounds`` of the benchmark's OmniD runs: the envs' workspace, which holds every object."""


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


def merge_command(parts: Sequence[Path], root: Path) -> list[str]:
    """`lerobot-edit-dataset` merging the local datasets ``parts`` (same features) into ``root`` (repo id
    ``local/<root name>``)."""
    return [
        str(BIN / "lerobot-edit-dataset"),
        f"--new_repo_id=local/{root.name}",
        f"--new_root={root}",
        "--operation.type=merge",
        f"--operation.repo_ids={json.dumps([f'local/{part.name}' for part in parts])}",
        f"--operation.roots={json.dumps([str(part) for part in parts])}",
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
