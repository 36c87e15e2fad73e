"""Does a policy use its cameras? The change of its action when it is given another episode's images.

    B=outputs/benchmark_mini
    python -m lerobot_omnid.diagnostics.image_use --root $B/data/select_apple_bcde \\
        --checkpoint $B/train/omnid/select_apple/checkpoints/last/pretrained_model

For each of the first ``--episodes`` episodes of a gym_omnid dataset, frame ``--frame`` goes through the
checkpoint as ``lerobot-eval`` runs it (pre- and postprocessor, ``select_action`` after a reset, the same
noise for every call) once with its own images and once with the images of the next episode (same
frame index, hence a similar arm pose, but the objects elsewhere), the state being its own both times.
Reported, for the action ``--ahead`` steps into the first chunk: the TCP position error (cm) against the
expert's action with its own and with the swapped images, and the mean distance between the two
predictions. A policy whose prediction does not move when the images are swapped acts from the state
alone. Works for any LeRobot policy trained on a dataset recorded by ``omnid-record`` (cameras calibrated
per frame included); the errors are in cm where the action's first three values are a position in m
(gym_omnid), in hundredths of the action's units otherwise (MetaWorld's position deltas).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch
from lerobot.datasets.lerobot_dataset import LeRobotDataset, LeRobotDatasetMetadata
from lerobot.utils.constants import ACTION, OBS_IMAGES, OBS_PREFIX

from lerobot_omnid.diagnostics.checkpoints import POSITION, load_policy


def chunk_action(
    policy, preprocessor, postprocessor, images: dict, state_item: dict, ahead: int
) -> np.ndarray:
    """Action ``ahead`` steps into the first chunk predicted from ``images`` and the rest of ``state_item``'s
    observation: its state and, where the cameras are calibrated per frame, its calibration columns."""
    policy.reset()
    observation = {
        key: value.unsqueeze(0)
        for key, value in state_item.items()
        if key.startswith(OBS_PREFIX) and not key.startswith(OBS_IMAGES)
    }
    observation.update({key: value.unsqueeze(0) for key, value in images.items()})
    observation["task"] = [state_item["task"]]
    torch.manual_seed(0)  # the same diffusion noise for both calls
    with torch.inference_mode():
        actions = [postprocessor(policy.select_action(preprocessor(observation)))]
        actions += [postprocessor(action) for action in policy._queues[ACTION]]
    if ahead >= len(actions):
        raise ValueError(f"--ahead: expected < {len(actions)} (the policy's executed chunk), got {ahead}")
    return actions[ahead].squeeze(0).cpu().numpy()


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--checkpoint", type=Path, required=True, help="a pretrained_model folder")
    parser.add_argument("--root", type=Path, required=True, help="a gym_omnid LeRobot dataset")
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--frame", type=int, default=10, help="frame index within each episode")
    parser.add_argument("--ahead", type=int, default=7, help="action index within the first chunk")
    parser.add_argument("--device", default="cpu")
    args = parser.parse_args()

    meta = LeRobotDatasetMetadata(f"local/{args.root.name}", root=args.root)
    if not 2 <= args.episodes <= meta.total_episodes:
        parser.error(f"--episodes: expected 2..{meta.total_episodes} (the dataset's), got {args.episodes}")
    episodes = list(range(args.episodes))
    dataset = LeRobotDataset(
        f"local/{args.root.name}", root=args.root, episodes=episodes, video_backend="pyav"
    )
    policy, preprocessor, postprocessor = load_policy(args.checkpoint, meta, args.device)
    image_keys = [key for key in policy.config.input_features if key.startswith("observation.images.")]
    starts = dataset.meta.episodes["dataset_from_index"]
    lengths = dataset.meta.episodes["length"]
    if args.frame + args.ahead >= min(lengths[: args.episodes]):
        parser.error(f"--frame + --ahead: expected < {min(lengths[: args.episodes])} (shortest episode)")
    items = [dataset[int(starts[ep]) + args.frame] for ep in episodes]
    expert = np.array([dataset[int(starts[ep]) + args.frame + args.ahead][ACTION].numpy() for ep in episodes])

    own, swapped = [], []
    for i, item in enumerate(items):
        other = items[(i + 1) % len(items)]
        own.append(
            chunk_action(
                policy, preprocessor, postprocessor, {k: item[k] for k in image_keys}, item, args.ahead
            )
        )
        swapped.append(
            chunk_action(
                policy, preprocessor, postprocessor, {k: other[k] for k in image_keys}, item, args.ahead
            )
        )
    own, swapped = np.array(own), np.array(swapped)

    def cm(a: np.ndarray, b: np.ndarray) -> float:
        return float(100 * np.linalg.norm(a[:, POSITION] - b[:, POSITION], axis=1).mean())

    print(
        f"{args.checkpoint}: frame {args.frame}, action {args.ahead} of the first chunk, {args.episodes} eps"
    )
    print(f"  TCP error vs expert: own images {cm(own, expert):.2f} cm, swapped {cm(swapped, expert):.2f} cm")
    print(f"  change of the action when the images are swapped: {cm(own, swapped):.3f} cm")


if __name__ == "__main__":
    main()
