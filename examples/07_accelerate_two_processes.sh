#!/usr/bin/env bash
# Step 7: data-parallel training with accelerate, two processes. On GPUs: one per GPU. Without CUDA the
# same command starts two CPU processes (torch.distributed with the gloo backend); LeRobot then reports
# "Effective batch size: B x 2". (`accelerate launch --cpu` starts a single process, whatever
# --num_processes says.)
set -euo pipefail
source "$(dirname "$0")/_config.sh"

accelerate launch --multi_gpu --num_processes 2 --num_machines 1 --mixed_precision no --dynamo_backend no \
  "$(command -v lerobot-train)" "${POLICY_FLAGS[@]}" "${COMMON_TRAIN_FLAGS[@]}" \
  --dataset.repo_id=local/select_apple_bcde --dataset.root="$OUT/data/select_apple_bcde" \
  --policy.cameras="$POLICY_TRAIN_CAMERAS" --steps="$STEPS" --save_freq="$STEPS" --output_dir="$OUT/train_bcde_2proc"
