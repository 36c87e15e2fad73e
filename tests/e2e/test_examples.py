"""The user workflow, run as a user runs it: the example scripts in order, at tiny sizes (slow)."""

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from lerobot_omnid.policy.modeling_omnid import OmniDPolicy

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "examples"
FAKE_HUB = Path(__file__).parents[1] / "fake_hub"

# Steps 4-8 start from the datasets and checkpoint of steps 1-3 (a module fixture): one worker.
pytestmark = [pytest.mark.slow, pytest.mark.xdist_group("examples")]

TINY_POLICY = (
    "--policy.d_model=32", "--policy.num_heads=2", "--policy.num_layers=1", "--policy.ffn_dim=64",
    "--policy.down_dims=[32,64]",
)  # fmt: skip


def workflow_env(out: Path) -> dict:
    """The example scripts' environment: everything below ``out``, tiny sizes."""
    env = dict(os.environ)
    env.update(
        OUT=str(out), EPISODES="2", FEWSHOT_EPISODES="2", IMAGE_SIZE="64", STEPS="2", FINETUNE_STEPS="2",
        BATCH_SIZE="2", EVAL_EPISODES="1", EPISODE_LENGTH="10", NUM_WORKERS="0", TRAIN_EVAL_EPISODES="1",
        # A small OmniD (the defaults' UNet alone has 250M parameters: ~25 s a chunk on 2 cores), same parts.
        VOLUME_SHAPE="[8,10,4]", POLICY_SIZE_FLAGS=" ".join(TINY_POLICY),
        PATH=f"{Path(sys.executable).parent}{os.pathsep}{env['PATH']}",
    )  # fmt: skip
    return env


def run_example(name: str, env: dict) -> subprocess.CompletedProcess:
    return subprocess.run(
        ["bash", str(EXAMPLES / name)], capture_output=True, text=True, env=env, timeout=900
    )


def example_log(results: dict[str, subprocess.CompletedProcess], name: str) -> str:
    result = results[name]
    assert result.returncode == 0, f"{name} failed:\n{result.stdout[-2000:]}\n{result.stderr[-4000:]}"
    return result.stdout + result.stderr


@pytest.fixture(scope="module")
def examples(tmp_path_factory) -> tuple[Path, dict, dict[str, subprocess.CompletedProcess]]:
    """Steps 1-3 in order, stopping at the first that fails; the steps after them start from their outputs."""
    out = tmp_path_factory.mktemp("examples")
    env = workflow_env(out)
    results = {}
    for name in ("01_record_datasets.sh", "02_train_omnid.sh", "03_evaluate.sh"):
        results[name] = run_example(name, env)
        if results[name].returncode != 0:
            break
    return out, env, results


def after_step_3(examples, name: str) -> dict[str, subprocess.CompletedProcess]:
    """Example ``name`` run on the outputs of steps 1-3."""
    _, env, _ = examples
    return {name: run_example(name, env)}


def success_info(eval_dir: Path) -> dict:
    info = json.loads((eval_dir / "eval_info.json").read_text())["overall"]
    assert info["n_episodes"] == 1 and info["video_paths"] and Path(info["video_paths"][0]).is_file()
    return info


def test_record_train_evaluate(examples):
    out, _, ran = examples
    example_log(ran, "01_record_datasets.sh")
    for name in ("select_apple_bcde", "select_apple_a", "select_chemistry_tube_a"):
        assert (out / "data" / name / "meta" / "info.json").is_file()
    log = example_log(ran, "02_train_omnid.sh")
    assert "Eval policy" in log or "eval" in log.lower()
    checkpoint = out / "train_bcde" / "checkpoints" / "last" / "pretrained_model"
    assert OmniDPolicy.from_pretrained(checkpoint).camera_keys == [
        f"observation.images.cam_{c}" for c in "bcde"
    ]
    example_log(ran, "03_evaluate.sh")
    for setting in ("id_id", "position_ood_id", "id_ood1"):
        success_info(out / f"eval_bcde_{setting}")


@pytest.fixture
def run_checkpoint(examples) -> tuple[Path, subprocess.CompletedProcess]:
    out, env, _ = examples
    checkpoint = out / "train_bcde" / "checkpoints" / "last" / "pretrained_model"
    return checkpoint, subprocess.run(
        [sys.executable, str(EXAMPLES / "08_run_checkpoint.py"), f"--checkpoint={checkpoint}",
         "--task=select_apple", "--seed=1", "--device=cpu", "--max-steps=3"],
        capture_output=True, text=True, env=env, timeout=300,
    )  # fmt: skip


def test_python_example_runs_the_checkpoint_for_one_episode(run_checkpoint):
    checkpoint, result = run_checkpoint
    assert checkpoint.is_dir(), "trained by 02_train_omnid.sh (test_record_train_evaluate)"
    assert result.returncode == 0, f"{result.stdout[-2000:]}\n{result.stderr[-4000:]}"
    lines = result.stdout.splitlines()
    # The env observes the checkpoint's cameras at its training image size (IMAGE_SIZE=64).
    assert "cameras cam_b, cam_c, cam_d, cam_e at 64x64 pixels" in lines
    assert re.fullmatch(r"select_apple, seed 1: (success after [1-3]|failure after 3) steps", lines[-1])


def test_finetune_on_camera_a_keeps_weights_and_takes_new_calibration(examples):
    out, _, _ = examples
    example_log(after_step_3(examples, "04_finetune_camera_a.sh"), "04_finetune_camera_a.sh")
    base = OmniDPolicy.from_pretrained(out / "train_bcde" / "checkpoints" / "last" / "pretrained_model")
    for task in ("select_apple", "select_chemistry_tube"):
        tuned = OmniDPolicy.from_pretrained(
            out / f"finetune_a_{task}" / "checkpoints" / "last" / "pretrained_model"
        )
        assert tuned.camera_keys == ["observation.images.cam_a"]
        dataset_info = json.loads((out / "data" / f"{task}_a" / "meta" / "info.json").read_text())
        expected = dataset_info["features"]["observation.images.cam_a"]["info"]["calibration"]
        assert tuned.config.camera_calibration == {"observation.images.cam_a": expected}
        # Fine-tuned from the checkpoint: two small steps leave the weights close to the base, not random.
        base_w = base.model.ofg.query_embed
        tuned_w = tuned.model.ofg.query_embed
        assert (tuned_w - base_w).abs().max() < 1e-2
        stats = json.loads((out / "data" / f"{task}_a" / "meta" / "stats.json").read_text())["action"]
        from safetensors.torch import load_file

        norm = load_file(
            next(
                (out / f"finetune_a_{task}" / "checkpoints" / "last" / "pretrained_model").glob(
                    "policy_preprocessor_step_*_normalizer_processor.safetensors"
                )
            )
        )
        assert norm["action.max"].tolist() == pytest.approx(stats["max"], rel=1e-5)
        success_info(out / f"eval_finetune_a_{task}")


def test_evaluate_on_a_camera_subset(examples):
    out, _, _ = examples
    example_log(after_step_3(examples, "05_eval_camera_subset.sh"), "05_eval_camera_subset.sh")
    success_info(out / "eval_bcde_on_bc")


@pytest.fixture
def push_and_evaluate(examples, tmp_path) -> tuple[Path, dict[str, subprocess.CompletedProcess]]:
    """06_push_to_hub.sh into a fake Hub, then lerobot-eval of the pushed folder in a fresh process."""
    _, env, _ = examples
    hub = tmp_path / "hub"
    env = dict(env, HUB_REPO_ID="someone/omnid_select_apple", OMNID_FAKE_HUB_DIR=str(hub),
               PYTHONPATH=f"{FAKE_HUB}{os.pathsep}{env.get('PYTHONPATH', '')}")  # fmt: skip
    ran = {"06_push_to_hub.sh": run_example("06_push_to_hub.sh", env)}
    if ran["06_push_to_hub.sh"].returncode == 0:
        pushed = hub / "someone" / "omnid_select_apple"
        ran["lerobot-eval"] = subprocess.run(
            [str(Path(sys.executable).parent / "lerobot-eval"), f"--policy.path={pushed}",
             "--policy.device=cpu", "--env.type=omnid", "--env.task=select_apple",
             "--env.cameras=[cam_b,cam_c,cam_d,cam_e]", "--env.image_size=64", "--env.episode_length=10",
             "--eval.n_episodes=1", "--eval.batch_size=1", f"--output_dir={tmp_path / 'eval_pushed'}"],
            capture_output=True, text=True, timeout=600,
        )  # fmt: skip
    return tmp_path, ran


def test_push_to_hub_folder_card_and_reload_in_fresh_process(push_and_evaluate):
    tmp_path, ran = push_and_evaluate
    hub = tmp_path / "hub"
    example_log(ran, "06_push_to_hub.sh")
    pushed = hub / "someone" / "omnid_select_apple"
    for name in (
        "model.safetensors",
        "config.json",
        "train_config.json",
        "README.md",
        "policy_preprocessor.json",
    ):
        assert (pushed / name).is_file(), name
    card = (pushed / "README.md").read_text()
    assert "## OmniD: cameras and calibration" in card and "`observation.images.cam_e`" in card
    assert "local/select_apple_bcde" in card
    # A fresh process loads the pushed folder and evaluates it.
    result = ran["lerobot-eval"]
    assert result.returncode == 0, result.stderr[-3000:]
    success_info(tmp_path / "eval_pushed")


def test_accelerate_two_processes(examples):
    out, _, _ = examples
    log = example_log(
        after_step_3(examples, "07_accelerate_two_processes.sh"), "07_accelerate_two_processes.sh"
    )
    assert "Effective batch size: 2 x 2 = 4" in log
    assert (
        out / "train_bcde_2proc" / "checkpoints" / "last" / "pretrained_model" / "model.safetensors"
    ).is_file()
