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

TRAIN_CAMERAS="[cam_b,cam_c,cam_d,cam_e]"            # for --env.cameras
POLICY_TRAIN_CAMERAS='["cam_b","cam_c","cam_d","cam_e"]'  # for --policy.cameras: JSON strings, which
                                                        # also parse when --policy.path loads a checkpoint
CHECKPOINT="$OUT/train_bcde/checkpoints/last/pretrained_model"
# OmniD settings for the benchmark's workspace (objects lie in x 0.3..0.8 m, y -0.3..0.35 m) and sampling
# with DDIM in 10 steps; see lerobot_omnid/configuration_omnid.py for every option.
POLICY_FLAGS=(
  --policy.type=omnid --policy.device="$DEVICE" --policy.push_to_hub=false
  --policy.volume_bounds="[[0.2,0.84],[-0.4,0.4],[0.0,0.32]]" --policy.volume_shape="[32,40,16]"
  --policy.backbone_layer=3 --policy.noise_scheduler_type=DDIM --policy.num_inference_steps=10
)
COMMON_TRAIN_FLAGS=(
  --dataset.video_backend=pyav --batch_size="$BATCH_SIZE" --num_workers="$NUM_WORKERS" --wandb.enable=false
)
