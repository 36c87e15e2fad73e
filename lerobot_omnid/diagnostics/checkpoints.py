"""What the diagnostics read from a run: a checkpoint loaded as ``lerobot-eval`` loads it, the gym_omnid
action's layout, and the frames of recorded expert episodes before their grasp with the grasp's place."""

from __future__ import annotations

from pathlib import Path

import torch
from lerobot.datasets.lerobot_dataset import LeRobotDataset
from lerobot.utils.constants import ACTION
from torch import Tensor
from tqdm import tqdm

POSITION, ROT6D, GRIPPER = slice(0, 3), slice(3, 9), 9  # layout of the gym_omnid action


def load_policy(checkpoint: Path, meta, device: str):
    """(policy, preprocessor, postprocessor) of a checkpoint, loaded as ``lerobot-eval`` loads it."""
    from lerobot.configs.policies import PreTrainedConfig
    from lerobot.policies import make_policy, make_pre_post_processors

    config = PreTrainedConfig.from_pretrained(checkpoint)
    config.pretrained_path = checkpoint
    config.device = device
    policy = make_policy(config, ds_meta=meta)
    policy.eval()
    preprocessor, postprocessor = make_pre_post_processors(
        policy_cfg=config,
        pretrained_path=str(checkpoint),
        preprocessor_overrides={"device_processor": {"device": device}},
    )
    return policy, preprocessor, postprocessor


def expert_frames(root: Path, frames: range) -> tuple[list[dict[str, Tensor]], Tensor]:
    """The dataset items of ``frames`` of every expert episode under ``root`` and, for each item, the x-y (m)
    where that episode's gripper first closes (N, 2): the object's place, unmoved before the grasp."""
    dataset = LeRobotDataset(f"local/{root.name}", root=root, video_backend="pyav")
    episodes, rows = dataset.meta.episodes, dataset.hf_dataset.with_format("torch")
    items, grasp = [], []
    for e in tqdm(range(dataset.meta.total_episodes), desc=f"frames {root.name}", unit="episode"):
        start, end = int(episodes["dataset_from_index"][e]), int(episodes["dataset_to_index"][e])
        actions = torch.stack([rows[i][ACTION] for i in range(start, end)])
        closing = (actions[:, GRIPPER] > 0.5).nonzero()
        if len(closing) == 0 or int(closing[0, 0]) <= max(frames):
            raise ValueError(f"{root} episode {e}: expected the gripper to close after frame {max(frames)}")
        xy = actions[int(closing[0, 0]), POSITION][:2]
        for f in frames:
            items.append(dataset[start + f])
            grasp.append(xy)
    return items, torch.stack(grasp)
