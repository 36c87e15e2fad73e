#!/usr/bin/env bash
# Step 4: few-shot fine-tuning on a new view. The B-E checkpoint is fine-tuned with `--policy.path` on the
# camera-A sets of the same task and of select_chemistry_tube, then evaluated with camera A only.
# What is kept and what is new: the learned weights come from the checkpoint (the OFG never sees a camera
# identity, so they fit any camera); the camera calibration comes from the new dataset's feature info and
# the state/action normalisation statistics from the new dataset (lerobot-train overrides the checkpoint's
# normaliser stats when it fine-tunes). `--policy.cameras` names the dataset's cameras to use.
set -euo pipefail
source "$(dirname "$0")/_config.sh"

for task in select_apple select_chemistry_tube; do
  lerobot-train --policy.path="$CHECKPOINT" --policy.device="$DEVICE" --policy.push_to_hub=false \
    --policy.cameras='["cam_a"]' "${COMMON_TRAIN_FLAGS[@]}" \
    --dataset.repo_id="local/${task}_a" --dataset.root="$OUT/data/${task}_a" \
    --steps="$FINETUNE_STEPS" --save_freq="$FINETUNE_STEPS" --output_dir="$OUT/finetune_a_${task}"
  lerobot-eval --policy.path="$OUT/finetune_a_${task}/checkpoints/last/pretrained_model" --policy.device="$DEVICE" \
    --env.type=omnid --env.task="$task" --env.cameras="[cam_a]" --env.image_size="$IMAGE_SIZE" \
    --env.episode_length="$EPISODE_LENGTH" --eval.n_episodes="$EVAL_EPISODES" --eval.batch_size=1 \
    --output_dir="$OUT/eval_finetune_a_${task}"
done
