"""Run a trained OmniD checkpoint for one episode in a gym_omnid env and print whether it succeeded.

The Python counterpart of ``03_evaluate.sh`` (``lerobot-eval``), in the open: load the policy and the
pre/post-processors LeRobot saved beside it, build the env with the policy's cameras at the size of its
training images, and step it::

    python examples/08_run_checkpoint.py --task select_apple --seed 1 \\
        --checkpoint outputs/examples/train_bcde/checkpoints/last/pretrained_model

``--checkpoint`` is a ``pretrained_model`` folder written by ``lerobot-train`` (``config.json``,
``model.safetensors``, ``policy_preprocessor.json``, ``policy_postprocessor.json`` and their statistics).
Ends with one line: ``<task>, seed <seed>: success|failure after <n> steps``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import gym_omnid  # registers gym_omnid/<task>
import gymnasium as gym
import torch
from lerobot.envs.utils import preprocess_observation
from lerobot.policies.factory import make_pre_post_processors
from lerobot.utils.constants import OBS_IMAGES
from tqdm import tqdm

from lerobot_omnid.policy.configuration_omnid import OmniDConfig
from lerobot_omnid.policy.modeling_omnid import OmniDPolicy


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--checkpoint", type=Path, required=True, help="pretrained_model folder")
    parser.add_argument("--task", default="select_apple", choices=gym_omnid.TASKS)
    parser.add_argument("--layout", default="id", choices=gym_omnid.LAYOUTS, help="object placement")
    parser.add_argument("--background", default="id", choices=gym_omnid.BACKGROUNDS, help="table texture")
    parser.add_argument("--seed", type=int, default=0, help="env seed of the episode")
    parser.add_argument(
        "--device", default=None, help="torch device (default: the checkpoint's, if available)"
    )
    parser.add_argument(
        "--max-steps",
        type=int,
        default=gym_omnid.MAX_EPISODE_STEPS,
        help=f"time limit of the episode, env steps (default {gym_omnid.MAX_EPISODE_STEPS})",
    )
    args = parser.parse_args(argv)
    if not (args.checkpoint / "config.json").is_file():
        parser.error(
            f"--checkpoint: expected a pretrained_model folder with config.json, got {args.checkpoint}"
        )
    if args.max_steps < 1:
        parser.error(f"--max-steps: expected a positive number of env steps, got {args.max_steps}")
    return args


def load_policy(checkpoint: Path, device: str | None) -> OmniDPolicy:
    """The checkpoint's policy in eval mode on ``device``.

    The backbone's pretrained weights are part of ``model.safetensors``: do not fetch them again (a
    torchvision weights name would need the network, a local file the training machine).
    """
    overrides = ["--pretrained_backbone_weights=null"] + ([f"--device={device}"] if device else [])
    config = OmniDConfig.from_pretrained(checkpoint, cli_overrides=overrides)
    return OmniDPolicy.from_pretrained(checkpoint, config=config)


def make_env(policy: OmniDPolicy, task: str, layout: str, background: str, max_steps: int) -> gym.Env:
    """The env observing the policy's cameras, at the (height, width) of its training images, with every
    frame's calibration in the observation when the policy reads it per frame (trained on
    ``omnid-record``'s default per-frame calibration columns)."""
    cameras = [key.removeprefix(f"{OBS_IMAGES}.") for key in policy.camera_keys]
    sizes = {tuple(policy.config.image_features[key].shape[1:]) for key in policy.camera_keys}
    if len(sizes) != 1:
        raise ValueError(f"the checkpoint's cameras have different image sizes {sorted(sizes)}")
    return gym.make(
        f"gym_omnid/{task}",
        cameras=tuple(cameras),
        layout=layout,
        background=background,
        image_size=sizes.pop(),
        per_frame_calibration=bool(policy.config.frame_calibration),
        max_episode_steps=max_steps,
    )


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    policy = load_policy(args.checkpoint, args.device)
    # As lerobot-eval: the saved pipelines (normalisation statistics), with the device of this run.
    preprocessor, postprocessor = make_pre_post_processors(
        policy.config,
        pretrained_path=str(args.checkpoint),
        preprocessor_overrides={"device_processor": {"device": str(policy.config.device)}},
    )
    env = make_env(policy, args.task, args.layout, args.background, args.max_steps)
    try:
        image_size = env.unwrapped.image_size
        print(f"cameras {', '.join(env.unwrapped.cameras)} at {image_size[0]}x{image_size[1]} pixels")
        policy.reset()
        observation, info = env.reset(seed=args.seed)
        steps, done = 0, False
        with torch.inference_mode(), tqdm(total=args.max_steps, desc=f"{args.task} episode") as progress:
            while not done:
                # pixels[<cam>] (H, W, 3) uint8 -> observation.images.<cam> (1, 3, H, W) in [0, 1];
                # agent_pos -> observation.state (1, state_dim); extrinsics.<cam> / intrinsics.<cam> ->
                # observation.extrinsics.<cam> / observation.intrinsics.<cam> (per-frame calibration).
                batch = preprocess_observation(observation)
                batch["task"] = [env.unwrapped.task_description]
                action = postprocessor(policy.select_action(preprocessor(batch)))
                observation, _, terminated, truncated, info = env.step(action[0].numpy())
                steps += 1
                done = terminated or truncated
                progress.update()
    finally:
        env.close()
    outcome = "success" if info["is_success"] else "failure"
    print(f"{args.task}, seed {args.seed}: {outcome} after {steps} steps")


if __name__ == "__main__":
    main()
