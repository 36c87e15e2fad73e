#!/usr/bin/env bash
# Step 3: evaluate the B-E checkpoint with lerobot-eval: in distribution, position OOD (objects 10-20 cm
# around the training square) and an unseen table texture. Each writes eval_info.json and videos.
set -euo pipefail
source "$(dirname "$0")/_config.sh"

for setting in "id id" "position_ood id" "id ood1"; do
  read -r layout background <<< "$setting"
  lerobot-eval --policy.path="$CHECKPOINT" --policy.device="$DEVICE" \
    --env.type=omnid --env.task=select_apple --env.layout="$layout" --env.background="$background" \
    --env.cameras="$TRAIN_CAMERAS" --env.image_size="$IMAGE_SIZE" --env.episode_length="$EPISODE_LENGTH" \
    --eval.n_episodes="$EVAL_EPISODES" --eval.batch_size=1 --output_dir="$OUT/eval_bcde_${layout}_${background}"
done
