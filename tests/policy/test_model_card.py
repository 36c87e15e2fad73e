"""The OmniD section of the Hub model card: cameras, calibration, evaluation results."""

import json
from types import SimpleNamespace

from huggingface_hub import ModelCard
from omnid_testing import tiny_config

from lerobot_omnid.policy.modeling_omnid import OmniDPolicy


def test_card_states_cameras_calibration_and_eval_results(tmp_path, monkeypatch):
    monkeypatch.setattr(ModelCard, "validate", lambda self, *a, **k: None)  # validation is a Hub request
    policy = OmniDPolicy(tiny_config())
    card = policy.generate_model_card("local/tiny", "omnid", None, None)
    assert "Not evaluated before this push." in card.content
    row = "`observation.images.cam_b` | 64 x 64 | 32.0 | 32.0 | 31.5 | 31.5 | (1.300, 0.000, 0.600)"
    assert row in card.content

    eval_dir = tmp_path / "eval_position_ood"
    eval_dir.mkdir()
    (eval_dir / "eval_info.json").write_text(json.dumps({"overall": {"pc_success": 40.0, "n_episodes": 5}}))
    cfg = SimpleNamespace(output_dir=tmp_path, steps=10, batch_size=2, seed=0, optimizer=None, dataset=None)
    card = policy.generate_model_card("local/tiny", "omnid", None, None, cfg=cfg)
    assert "| eval_position_ood | 5 | 40.0 |" in card.content


def test_card_of_a_policy_calibrated_per_frame(monkeypatch):
    """A checkpoint trained on a default (per-frame) recording has no static calibration to print."""
    monkeypatch.setattr(ModelCard, "validate", lambda self, *a, **k: None)
    keys = [f"observation.images.{c}" for c in ("cam_b", "cam_c", "cam_d", "cam_e")]
    policy = OmniDPolicy(tiny_config(camera_calibration={}, frame_calibration=keys))
    card = policy.generate_model_card("local/tiny", "omnid", None, None)
    assert "`observation.images.cam_c` | calibrated per frame" in card.content
