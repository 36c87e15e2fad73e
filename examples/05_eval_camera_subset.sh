#!/usr/bin/env bash
# Step 5: evaluate with other cameras than the policy was trained with, through lerobot-eval options only:
# the B-E checkpoint on cameras B and C. `--policy.cameras` picks the policy's image inputs (their
# calibration is in the checkpoint); a camera the checkpoint has no calibration for is given with
# `--policy.calibration_path=rig.json` (schema in lerobot_omnid/calibration_file.py).
set -euo pipefail
source "$(dirname "$0")/_config.sh"

lerobot-eval --policy.path="$CHECKPOINT" --policy.device="$DEVICE" --policy.cameras='["cam_b","cam_c"]' \
  --env.type=omnid --env.task=select_apple --env.cameras="[cam_b,cam_c]" --env.image_size="$IMAGE_SIZE" \
  --env.episode_length="$EPISODE_LENGTH" --eval.n_episodes="$EVAL_EPISODES" --eval.batch_size=1 \
  --output_dir="$OUT/eval_bcde_on_bc"
