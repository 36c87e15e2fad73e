"""``omnid-offline-eval``: open-loop action error of a LeRobot policy checkpoint on recorded expert episodes.

Each episode of a gym_omnid dataset is replayed frame by frame through the exact path ``lerobot-eval`` uses
(policy preprocessor, ``select_action`` with its observation history and action queue, postprocessor), but
the observations come from the expert's recording instead of the policy's own rollout. The policy's action
at every frame is compared with the expert's: TCP position error (cm), rotation error (deg, between the
6D rotations) and gripper error (command units, 0 open .. 1 closed).

Success rates of short CPU runs are often 0 % for every method, which says nothing about which one is
closer; this error is informative at any training length and isolates the representation from compounding
closed-loop error. It is a diagnostic next to the success rate, not a replacement. For scale, the same
errors are given for holding the measured pose and gripper of each frame (``hold``): expert actions are
small steps from the current pose, so a policy has learned something only when it beats that.

    omnid-offline-eval --checkpoint outputs/train/checkpoints/last/pretrained_model \\
        --root outputs/data/select_apple_heldout --out offline_eval.json
"""

from __future__ import annotations

import argparse
import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import torch
from gym_omnid.rotations import matrix_from_rot6d
from lerobot.utils.constants import ACTION, OBS_STATE
from tqdm import tqdm

from lerobot_omnid.calibration.frame_columns import extrinsics_key, intrinsics_key
from lerobot_omnid.cli import positive_int
from lerobot_omnid.diagnostics.checkpoints import GRIPPER, POSITION, ROT6D, load_policy

if TYPE_CHECKING:
    from lerobot.configs.policies import PreTrainedConfig

# The gym_omnid state starts with the measured pose and gripper in the action's layout: as an action it
# means "stay where you are", the reference a policy that learned anything must beat.
ACTION_DIM = GRIPPER + 1
OUTPUT_NAME = "offline_eval.json"


def rotation_angle_deg(rot6d_a: np.ndarray, rot6d_b: np.ndarray) -> float:
    """Angle (deg) of the relative rotation between two 6D rotations (6,)."""
    a, b = matrix_from_rot6d(rot6d_a), matrix_from_rot6d(rot6d_b)
    cos_angle = np.clip((np.trace(a.T @ b) - 1.0) / 2.0, -1.0, 1.0)
    return math.degrees(math.acos(cos_angle))


def action_errors(predicted: np.ndarray, expert: np.ndarray) -> dict[str, float]:
    """Errors between a predicted and an expert action, both (10,) gym_omnid actions."""
    return {
        "position_cm": float(np.linalg.norm(predicted[POSITION] - expert[POSITION]) * 100.0),
        "rotation_deg": rotation_angle_deg(predicted[ROT6D], expert[ROT6D]),
        "gripper": float(abs(predicted[GRIPPER] - expert[GRIPPER])),
    }


def policy_inputs(config: PreTrainedConfig) -> list[str]:
    """The dataset keys a policy reads at every frame: its input features and, for an OmniD policy with
    cameras calibrated per frame (``frame_calibration``), their calibration columns, which OmniD keeps out
    of its input features (they are neither normalised nor state) but reads from every observation."""
    columns = [
        column
        for key in getattr(config, "frame_calibration", None) or ()
        for column in (extrinsics_key(key), intrinsics_key(key))
    ]
    return [*config.input_features, *columns]


def evaluate_offline(
    checkpoint: Path, root: Path, repo_id: str | None = None, episodes: int | None = None, device: str = "cpu"
) -> dict:
    """Mean errors over every frame of the first ``episodes`` episodes (all by default) of a dataset.

    Returns ``{"checkpoint", "dataset", "episodes", "frames", "position_cm", "rotation_deg", "gripper",
    "hold": {"position_cm", "rotation_deg", "gripper"}, "per_episode": [{"episode", "frames",
    "position_cm", "rotation_deg", "gripper"}, ...]}``, where ``hold`` is the error of the reference
    policy that holds the measured pose and gripper of each frame (the expert's small step is its error).
    """
    from lerobot.datasets.lerobot_dataset import LeRobotDataset, LeRobotDatasetMetadata

    repo_id = repo_id or f"local/{root.name}"
    meta = LeRobotDatasetMetadata(repo_id, root=root)
    if episodes is not None and not 1 <= episodes <= meta.total_episodes:
        raise ValueError(f"episodes: expected 1..{meta.total_episodes} (the dataset's), got {episodes}")
    selected = list(range(episodes or meta.total_episodes))
    dataset = LeRobotDataset(repo_id, root=root, episodes=selected, video_backend="pyav")
    policy, preprocessor, postprocessor = load_policy(checkpoint, meta, device)
    inputs = policy_inputs(policy.config)
    missing = [key for key in inputs if key not in meta.features]
    if missing:
        raise ValueError(
            f"dataset {root}: the policy's inputs {missing} are missing (it has {list(meta.features)})"
        )

    per_frame: dict[int, list[dict[str, float]]] = {}
    hold: list[dict[str, float]] = []
    previous_episode = None
    for index in tqdm(range(len(dataset)), desc=f"offline eval {root.name}", unit="frame"):
        item = dataset[index]
        episode = int(item["episode_index"])
        if episode != previous_episode:
            policy.reset()  # a new episode: empty observation history and action queue
            previous_episode = episode
        observation = {key: item[key].unsqueeze(0) for key in inputs}
        observation["task"] = [item["task"]]
        with torch.inference_mode():
            action = postprocessor(policy.select_action(preprocessor(observation)))
        predicted = action.squeeze(0).cpu().numpy()
        expert = item[ACTION].numpy()
        per_frame.setdefault(episode, []).append(action_errors(predicted, expert))
        hold.append(action_errors(item[OBS_STATE].numpy()[:ACTION_DIM], expert))

    def mean(rows: Sequence[dict[str, float]], key: str) -> float:
        return float(np.mean([row[key] for row in rows]))

    frames = [row for rows in per_frame.values() for row in rows]
    metrics = ("position_cm", "rotation_deg", "gripper")
    return {
        "checkpoint": str(checkpoint),
        "dataset": str(root),
        "episodes": len(per_frame),
        "frames": len(frames),
        **{key: mean(frames, key) for key in metrics},
        "hold": {key: mean(hold, key) for key in metrics},
        "per_episode": [
            {"episode": ep, "frames": len(rows), **{key: mean(rows, key) for key in metrics}}
            for ep, rows in per_frame.items()
        ],
    }


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="omnid-offline-eval", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--checkpoint", type=Path, required=True, help="a pretrained_model folder")
    parser.add_argument("--root", type=Path, required=True, help="local root of a recorded dataset")
    parser.add_argument("--repo-id", help="the dataset's repo id (default: local/<root folder name>)")
    parser.add_argument("--episodes", type=positive_int, help="evaluate the first N episodes (default: all)")
    parser.add_argument("--device", default="cpu", help="torch device (default: cpu)")
    parser.add_argument("--out", type=Path, help=f"write the result as JSON here (e.g. .../{OUTPUT_NAME})")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    for option, path in (("--checkpoint", args.checkpoint / "config.json"), ("--root", args.root / "meta")):
        if not path.exists():
            parser.error(f"{option}: expected {path} to exist, it does not")
    try:
        result = evaluate_offline(args.checkpoint, args.root, args.repo_id, args.episodes, args.device)
    except ValueError as error:
        parser.error(str(error))
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(
        f"{result['episodes']} episodes, {result['frames']} frames: position {result['position_cm']:.2f} cm, "
        f"rotation {result['rotation_deg']:.2f} deg, gripper {result['gripper']:.3f} "
        f"(holding the measured pose: position {result['hold']['position_cm']:.2f} cm, "
        f"gripper {result['hold']['gripper']:.3f})"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
