"""Can OmniD's image encoder learn where the object is? A direct regression probe, no diffusion head.

    B=outputs/benchmark_mini
    python -m lerobot_omnid.diagnostics.position_probe --root $B/data/select_apple_bcde \\
        --config $B/train/omnid/select_apple/checkpoints/last/pretrained_model \\
        --set plane_readout=\\"keypoints\\" --set compressed_channels=16

A fresh encoder (backbone + OFG, or the spatial-softmax pooling with ``--set use_ofg=false``) is built from
the checkpoint's ``config.json`` (its cameras and calibration; its weights are not loaded), with a small
MLP on its image condition, and trained to regress the gripper's x-y position at the first frame where the
expert closes it (where the object was grasped), from frames 0, 4, ..., 20 of each episode: the object's
position, which only the images show. The last ``--test-episodes`` episodes are held out. Printed every 25
steps: the held-out error (cm) and, for scale, the error of always predicting the training mean. An encoder
that stays at the mean for many steps gives the diffusion head, whose gradient carries far less of this
signal, nothing to learn from in a short run.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import torch
from lerobot.configs.policies import PreTrainedConfig
from torch import Tensor, nn
from tqdm import tqdm

from lerobot_omnid.diagnostics.checkpoints import expert_frames
from lerobot_omnid.policy.modeling_omnid import OmniDPolicy

FRAMES = range(0, 21, 4)  # before any expert grasp in distribution (the first close is at frame 22 or later)
SCALE_M = 0.03  # targets in units of 3 cm


def load_frames(root: Path, keys: list[str]) -> tuple[Tensor, Tensor, Tensor]:
    """Images (N, S, 3, H, W) of ``FRAMES`` of every episode, grasp x-y (N, 2) and episode index (N,)."""
    items, grasp = expert_frames(root, FRAMES)
    images = torch.stack([torch.stack([item[k] for k in keys]) for item in items])
    return images, grasp, torch.tensor([int(item["episode_index"]) for item in items])


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--root", type=Path, required=True, help="a gym_omnid LeRobot dataset")
    parser.add_argument("--config", type=Path, required=True, help="a pretrained_model folder (config only)")
    parser.add_argument("--set", action="append", default=[], help="config override KEY=JSON_VALUE")
    parser.add_argument("--steps", type=int, default=150)
    parser.add_argument("--batch-size", type=int, default=16)
    parser.add_argument("--lr", type=float, default=3e-4)
    parser.add_argument("--test-episodes", type=int, default=10)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    config = PreTrainedConfig.from_pretrained(args.config)
    for item in args.set:
        key, _, value = item.partition("=")
        if not hasattr(config, key):
            raise ValueError(f"--set {item}: the config has no field {key!r}")
        setattr(config, key, json.loads(value))
    config.__post_init__()  # re-validate after the overrides
    torch.manual_seed(args.seed)
    policy = OmniDPolicy(config).train()
    model = policy.model
    images, grasp, episode = load_frames(args.root, policy.camera_keys)
    is_test = episode >= episode.max() + 1 - args.test_episodes
    train_index, test_index = (~is_test).nonzero()[:, 0], is_test.nonzero()[:, 0]
    target = (grasp - grasp[train_index].mean(dim=0)) / SCALE_M

    pix_T_cam, cam_T_world = policy.camera_matrices(1, tuple(images.shape[-2:]))
    encoder = model.ofg if config.use_ofg else model.pool
    head = nn.Sequential(nn.Linear(model.image_cond_dim, 256), nn.ReLU(), nn.Linear(256, 2))
    parameters = [*model.backbone.parameters(), *encoder.parameters(), *head.parameters()]
    optimizer = torch.optim.AdamW(parameters, lr=args.lr, betas=(0.95, 0.999), weight_decay=1e-6)

    def predict(index: Tensor) -> Tensor:
        n = len(index)
        condition, _ = model.encode_images(
            images[index][:, None], pix_T_cam.expand(n, -1, -1, -1), cam_T_world.expand(n, -1, -1, -1)
        )
        return head(condition[:, 0])

    baseline_cm = (target[test_index] * SCALE_M * 100).norm(dim=-1).mean()
    for step in tqdm(range(1, args.steps + 1), desc="probe", unit="step"):
        batch = train_index[torch.randint(len(train_index), (args.batch_size,))]
        loss = (predict(batch) - target[batch]).square().mean()
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        if step % 25 == 0 or step == args.steps:
            with torch.no_grad():
                model.eval()
                error = (predict(test_index) - target[test_index]).norm(dim=-1).mean() * SCALE_M * 100
                model.train()
            tqdm.write(
                f"step {step}: train loss {loss.item():.3f}, held-out error {error:.2f} cm "
                f"(predicting the mean: {baseline_cm:.2f} cm)"
            )


if __name__ == "__main__":
    main()
