#!/usr/bin/env bash
# Step 2: train OmniD on cameras B-E with LeRobot's own training loop, evaluating in the env halfway and at
# the end (--env_eval_freq). The checkpoint lands in $OUT/train_bcde/checkpoints/last/pretrained_model.
set -euo pipefail
source "$(dirname "$0")/_config.sh"
: "${TRAIN_EVAL_EPISODES:=2}"         # episodes of each in-training evaluation

lerobot-train "${POLICY_FLAGS[@]}" "${COMMON_TRAIN_FLAGS[@]}" \
  --dataset.repo_id=local/select_apple_bcde --dataset.root="$OUT/data/select_apple_bcde" \
  --policy.cameras="$POLICY_TRAIN_CAMERAS" \
  --env.type=omnid --env.task=select_apple --env.cameras="$TRAIN_CAMERAS" --env.image_size="$IMAGE_SIZE" \
  --env.episode_length="$EPISODE_LENGTH" --env_eval_freq=$(( (STEPS + 1) / 2 )) \
  --eval.n_episodes="$TRAIN_EVAL_EPISODES" --eval.batch_size=1 \
  --steps="$STEPS" --save_freq="$STEPS" --output_dir="$OUT/train_bcde"
