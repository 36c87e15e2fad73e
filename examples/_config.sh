# Shared settings of the example scripts; every value can be overridden from the environment, e.g.
#   EPISODES=5 STEPS=100 bash examples/02_train_omnid.sh
# The defaults are the paper's protocol sizes (50 episodes, 10-episode few-shot sets); on a 2-core CPU use
# the main job (`make demo`) or smaller values.
: "${OUT:=outputs/examples}"          # everything is written below this folder
: "${DEVICE:=cpu}"                    # torch device: cpu or cuda
: "${EPISODES:=50}"                   # expert episodes of the training set (cameras B-E)
: "${FEWSHOT_EPISODES:=10}"           # expert episodes of each camera-A fine-tuning set
: "${IMAGE_SIZE:=128}"                # square camera images, pixels
: "${STEPS:=20000}"                   # training steps
: "${FINETUNE_STEPS:=5000}"           # fine-tuning steps
: "${BATCH_SIZE:=16}"
: "${EVAL_EPISODES:=50}"              # episodes per evaluation setting
: "${EPISODE_LENGTH:=200}"            # time limit of an evaluation episode, env steps (10 per second)
: "${NUM_WORKERS:=2}"                 # dataloader workers
: "${VOLUME_SHAPE:=[32,40,16]}"       # OmniD's feature volume: cells along x, y, z of the workspace box
: "${POLICY_SIZE_FLAGS:=}"            # more --policy.* options for a new policy, space-separated, e.g. a
                                      # quick run's sizes: "--policy.d_model=32 --policy.down_dims=[32,64]"

# The python of the environment the lerobot commands come from (the activated .venv; else the repo's
# .venv), to read the benchmark's shared names from gym_omnid; override with PYTHON=...
if [ -z "${PYTHON:-}" ]; then
  if command -v lerobot-train > /dev/null; then PYTHON="$(dirname "$(command -v lerobot-train)")/python"
  else PYTHON="$(dirname "${BASH_SOURCE[0]}")/../.venv/bin/python"; fi
  [ -x "$PYTHON" ] || PYTHON=python
fi
gym_omnid_json() {  # a name of gym_omnid as compact JSON
  "$PYTHON" -c "import json, gym_omnid; print(json.dumps(gym_omnid.$1, separators=(',', ':')))"
}
# Cameras B-E, for --env.cameras ([cam_b,...]) and --policy.cameras (JSON strings, which also parse when
# --policy.path loads a checkpoint); the workspace box (metres, robot base frame) for --policy.volume_bounds.
TRAIN_CAMERAS=$("$PYTHON" -c 'import gym_omnid; print("[" + ",".join(gym_omnid.TRAIN_CAMERAS) + "]")')
POLICY_TRAIN_CAMERAS=$(gym_omnid_json TRAIN_CAMERAS)
WORKSPACE_BOUNDS=$(gym_omnid_json WORKSPACE_BOUNDS)
CHECKPOINT="$OUT/train_bcde/checkpoints/last/pretrained_model"
# OmniD settings: its volume is the benchmark's workspace (gym_omnid.WORKSPACE_BOUNDS, which holds every
# object position), sampling with DDIM in 10 steps; see lerobot_omnid/policy/configuration_omnid.py for
# every option.
POLICY_FLAGS=(
  --policy.type=omnid --policy.device="$DEVICE" --policy.push_to_hub=false
  --policy.volume_bounds="$WORKSPACE_BOUNDS" --policy.volume_shape="$VOLUME_SHAPE"
  --policy.backbone_layer=3 --policy.noise_scheduler_type=DDIM --policy.num_inference_steps=10
)
read -r -a _size_flags <<< "$POLICY_SIZE_FLAGS"  # split on spaces, no glob expansion of [..]
POLICY_FLAGS+=("${_size_flags[@]}")
COMMON_TRAIN_FLAGS=(
  --dataset.video_backend=pyav --batch_size="$BATCH_SIZE" --num_workers="$NUM_WORKERS" --wandb.enable=false
)
