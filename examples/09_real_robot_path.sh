#!/usr/bin/env bash
# Step 9: the real-robot path, run on the simulated robot. What a user of a real arm runs, with the sim
# standing in for the arm (--robot.type=omnid_sim) and the scripted expert for the leader arm
# (--teleop.type=omnid_expert); walkthrough and the differences from a real arm: docs/real_robot.md.
#   1. lerobot-record: LeRobot's own recorder, one episode per run (one sim scene per robot connection),
#      merged into one dataset by lerobot-edit-dataset;
#   2. omnid-sim-calibration: the calibration file of the sim cameras (a real rig: omnid-calibrate);
#   3. omnid-attach-calibration: checks it against the dataset and writes it into meta/info.json;
#   4. lerobot-train --policy.type=omnid on that dataset;
#   5. lerobot-rollout --strategy.type=base --inference.type=sync: the checkpoint drives the sim robot.
# The robot's cameras get their own names (front, left, ...), not the env's: the names flow from the
# robot through the dataset and the checkpoint back to the robot.
set -euo pipefail
source "$(dirname "$0")/_config.sh"
: "${SIM_EPISODES:=$EPISODES}"        # episodes recorded with lerobot-record (one run each)
: "${SIM_EPISODE_TIME_S:=10}"         # seconds per recorded episode at 10 Hz (the select_apple expert needs ~7)
: "${ROLLOUT_TIME_S:=20}"             # seconds of the rollout (the env's episodes last at most 20)
: "${ROLLOUT_SEED:=100000}"           # scene of the rollout, not one of the recorded ones (seeds 0, 1, ...)

TASK=select_apple
TASK_TEXT="put the apple in the bowl"   # the env's instruction for this task (envs/README.md)
DATA="$OUT/data/sim_$TASK"
RIG="$OUT/sim_rig.yaml"
SIM_CHECKPOINT="$OUT/train_sim/checkpoints/last/pretrained_model"
cam() { echo "{source: $1, width: $IMAGE_SIZE, height: $IMAGE_SIZE, fps: 10}"; }
# OmniD at the benchmark's CPU size (the `mini` profile, docs/benchmark.md) on top of the other examples'
# flags: synchronous deployment waits for every new action chunk, 0.6 s on one CPU core at 64 px at this
# size and 9 s at the other examples' 128 px size (benchmarks/bench_select_action.py, docs/real_robot.md).
CPU_SIZE_FLAGS=(
  --policy.volume_shape="[16,20,8]" --policy.d_model=64 --policy.num_layers=2 --policy.checkpoint_sampling=false
  --policy.plane_readout=keypoints --policy.compressed_channels=16 --policy.down_dims="[128,256,512]"
  --policy.prediction_type=sample
)
ROBOT_FLAGS=(
  --robot.type=omnid_sim --robot.task="$TASK"
  --robot.cameras="{front: $(cam cam_b), left: $(cam cam_c), right: $(cam cam_d), back_left: $(cam cam_e)}"
)

# 1. Record, one lerobot-record run and one dataset per episode (the sim resets its scene only when it
# connects; LeRobot tells a robot nothing about episodes), then merge them with LeRobot's own
# lerobot-edit-dataset (adding episodes with lerobot-record --resume needs the `deepdiff` package of
# LeRobot's hardware extras). The expert rebuilds the robot's scene from the same task and seed (LeRobot
# gives a teleoperator no access to the robot), so both get the episode's seed. --dataset.no_stamp
# keeps the repo id as given (LeRobot appends a date otherwise).
has_episode() {  # a dataset root holding at least one saved episode
  [ -f "$1/meta/info.json" ] &&
    "$PYTHON" -c 'import json, sys; sys.exit(json.load(open(sys.argv[1]))["total_episodes"] < 1)' "$1/meta/info.json"
}
repo_ids=() roots=()
for (( seed = 0; seed < SIM_EPISODES; seed++ )); do
  root="$OUT/data/sim_runs/${TASK}_seed$seed"
  repo_ids+=("'local/${TASK}_seed$seed'") roots+=("'$root'")
  has_episode "$root" && continue
  rm -rf "$root"  # an interrupted run
  lerobot-record "${ROBOT_FLAGS[@]}" --robot.seed="$seed" \
    --teleop.type=omnid_expert --teleop.task="$TASK" --teleop.seed="$seed" \
    --dataset.repo_id="local/${TASK}_seed$seed" --dataset.root="$root" --dataset.no_stamp=true \
    --dataset.single_task="$TASK_TEXT" --dataset.fps=10 --dataset.num_episodes=1 \
    --dataset.episode_time_s="$SIM_EPISODE_TIME_S" --dataset.reset_time_s=0 --dataset.push_to_hub=false \
    --play_sounds=false --display_data=false
done
rm -rf "$DATA"
join() { local IFS=,; echo "[$*]"; }
lerobot-edit-dataset --new_repo_id="local/sim_$TASK" --new_root="$DATA" --push_to_hub=false \
  --operation.type=merge --operation.repo_ids="$(join "${repo_ids[@]}")" --operation.roots="$(join "${roots[@]}")"

# 2-3. Calibrate and attach: the same robot flags give the same cameras and image size.
omnid-sim-calibration "${ROBOT_FLAGS[@]}" --output="$RIG"
omnid-attach-calibration --root "$DATA" --calibration "$RIG" --no-backup \
  --volume-bounds $("$PYTHON" -c 'import gym_omnid; print(*[v for axis in gym_omnid.WORKSPACE_BOUNDS for v in axis])')

# 4. Train on every camera of the dataset (the calibration comes from its feature info).
lerobot-train "${POLICY_FLAGS[@]}" "${CPU_SIZE_FLAGS[@]}" "${COMMON_TRAIN_FLAGS[@]}" \
  --dataset.repo_id="local/sim_$TASK" --dataset.root="$DATA" \
  --steps="$STEPS" --save_freq="$STEPS" --output_dir="$OUT/train_sim"

# 5. Deploy: LeRobot's rollout engine, synchronous inference (its async server only takes LeRobot's own
# policy types). --fps=10 is the sim's control rate; the sim has no rest pose to return to at the end.
lerobot-rollout --strategy.type=base --inference.type=sync "${ROBOT_FLAGS[@]}" --robot.seed="$ROLLOUT_SEED" \
  --policy.path="$SIM_CHECKPOINT" --policy.device="$DEVICE" --task="$TASK_TEXT" \
  --fps=10 --duration="$ROLLOUT_TIME_S" --return_to_initial_position=false --play_sounds=false
