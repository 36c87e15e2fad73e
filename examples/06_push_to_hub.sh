#!/usr/bin/env bash
# Step 6: train and push the checkpoint to the Hugging Face Hub with LeRobot's own upload
# (`huggingface-cli login` first). The model card states the cameras, their calibration, the training
# dataset and the evaluation results found in the run (the eval_info.json of --env_eval_freq evaluations
# are not saved by LeRobot; lerobot-eval results under the output folder are).
set -euo pipefail
source "$(dirname "$0")/_config.sh"
: "${HUB_REPO_ID:?set HUB_REPO_ID=<user>/<model> to push}"

lerobot-train "${POLICY_FLAGS[@]}" "${COMMON_TRAIN_FLAGS[@]}" \
  --dataset.repo_id=local/select_apple_bcde --dataset.root="$OUT/data/select_apple_bcde" \
  --policy.cameras="$POLICY_TRAIN_CAMERAS" --policy.push_to_hub=true --policy.repo_id="$HUB_REPO_ID" \
  --steps="$STEPS" --save_freq="$STEPS" --output_dir="$OUT/train_bcde_hub"
