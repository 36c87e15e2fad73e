#!/usr/bin/env bash
# Step 1: record LeRobot datasets with the scripted expert: select_apple seen by cameras B-E (training),
# and small camera-A sets of select_apple and select_chemistry_tube (few-shot fine-tuning on a new view).
# --static-calibration: each camera's calibration once, in its feature info, as the benchmark records it;
# the steps below follow it into checkpoints (config.json, the model card, --policy.calibration_path).
# Without the flag (omnid-record's default) it is written in every frame, so that datasets of different
# rigs merge with lerobot-edit-dataset (docs/calibration.md#per-frame-calibration-columns).
set -euo pipefail
source "$(dirname "$0")/_config.sh"

record() {  # root, then omnid-record options; a dataset that exists is kept
  local root=$1; shift
  [ -f "$root/meta/info.json" ] || omnid-record --image-size "$IMAGE_SIZE" --static-calibration --root "$root" \
    --repo-id "local/$(basename "$root")" "$@"
}
record "$OUT/data/select_apple_bcde" --task select_apple --episodes "$EPISODES" --cameras cam_b,cam_c,cam_d,cam_e
# Other seeds than the training set's, so the few-shot sets are new episodes.
record "$OUT/data/select_apple_a" --task select_apple --episodes "$FEWSHOT_EPISODES" --cameras cam_a --seed 100000
record "$OUT/data/select_chemistry_tube_a" --task select_chemistry_tube --episodes "$FEWSHOT_EPISODES" \
  --cameras cam_a --seed 100000
