"""The position probe (lerobot_omnid.diagnostics.position_extrapolation): the ridge probe extrapolates a
linear representation and not a saturating one, and the image condition it reads from LeRobot's DP."""

from __future__ import annotations

import pytest
import torch
from lerobot.policies.diffusion.modeling_diffusion import DiffusionPolicy
from omnid_testing import COMMITTED_SUMMARIES, tiny_diffusion_config

from lerobot_omnid.diagnostics import position_extrapolation as pe


def _representation(xy: torch.Tensor, saturate: bool) -> torch.Tensor:
    """12 features of a 2-D position: a fixed linear map (clamped to the training square if ``saturate``)."""
    torch.manual_seed(1)
    mixing = torch.randn(2, 12)
    seen = xy.clamp(-0.05, 0.05) if saturate else xy
    return seen @ mixing + 0.3


def test_probe_extrapolates_a_linear_representation_only():
    torch.manual_seed(0)
    train = torch.rand(200, 2) * 0.1 - 0.05  # a 10 cm training square
    validation = torch.rand(40, 2) * 0.1 - 0.05
    outside = torch.rand(40, 2) * 0.05 + 0.06  # 1-6 cm beyond its corner
    for saturate, expect_far in ((False, 0.05), (True, 3.0)):
        result = pe.probe(
            (_representation(train, saturate), train),
            (_representation(validation, saturate), validation),
            {"outside": (_representation(outside, saturate), outside)},
        )
        assert result["sets"]["validation (id)"]["probe_cm"] < 0.05
        far = result["sets"]["outside"]["probe_cm"]
        assert far < expect_far if not saturate else far > expect_far
        assert result["sets"]["outside"]["mean_cm"] > 10.0  # the training mean is far from the corner
        assert result["ridge_weight"] in pe.RIDGE_WEIGHTS


def test_fit_ridge_shrinks_towards_the_mean():
    x = torch.randn(50, 3, dtype=torch.float64)
    y = x @ torch.tensor([[1.0], [2.0], [-1.0]], dtype=torch.float64) + 5.0
    exact, shrunk = pe.fit_ridge(x, y, 1e-9), pe.fit_ridge(x, y, 1e3)
    torch.testing.assert_close(pe.predict(exact, x), y)
    assert (pe.predict(shrunk, x) - y.mean()).abs().max() < 0.1 * (y - y.mean()).abs().max()


def test_image_condition_of_diffusion_is_each_cameras_features():
    policy = DiffusionPolicy(tiny_diffusion_config()).eval()
    b, c = torch.rand(3, 3, 32, 32), torch.rand(3, 3, 32, 32)
    with torch.no_grad():
        both = pe.image_condition(policy, {"observation.images.cam_b": b, "observation.images.cam_c": c})
        alone = policy.diffusion.rgb_encoder(c)
    feature_dim = policy.diffusion.rgb_encoder.feature_dim
    assert both.shape == (3, 2 * feature_dim)
    torch.testing.assert_close(both[:, feature_dim:], alone)
    policy.config.use_separate_rgb_encoder_per_camera = True
    with pytest.raises(ValueError, match="use_separate_rgb_encoder_per_camera"):
        pe.image_condition(policy, {})


def test_table_shift_is_zero_for_twins_and_near_root_two_for_strangers():
    torch.manual_seed(0)
    train, reference, strangers = torch.randn(400, 6), torch.randn(300, 6), torch.randn(300, 6)
    assert pe.table_shift(train, reference, reference) == 0.0
    # unrelated frames: E|a - b| / E|a - mean| = sqrt(2) for independent Gaussians
    assert 1.3 < pe.table_shift(train, reference, strangers) < 1.5
    nudged = reference + 0.1 * torch.randn(300, 6)
    assert 0.05 < pe.table_shift(train, reference, nudged) < 0.15
    # units do not matter: each feature is standardised by the training frames
    units = torch.tensor([1.0, 10.0, 0.1, 3.0, 1e3, 1e-2])
    assert pe.table_shift(train * units, reference * units, nudged * units) == pytest.approx(
        pe.table_shift(train, reference, nudged)
    )


def test_report_only_sets_committed_summaries_side_by_side(tmp_path, capsys):
    """The committed summaries of two runs rebuild docs/results.md's probe tables with no checkpoint."""
    runs = ["position_tables_seed1002_cpu2.json", "position_tables_seed1001_cpu2.json"]
    assert (
        pe.main(["--out", str(tmp_path), "--report-only", *(str(COMMITTED_SUMMARIES / r) for r in runs)]) == 0
    )
    report = (tmp_path / "report.md").read_text()
    assert "| validation (id) | 0.74 | 2.30 | 0.82 | 0.96 | 4.47 |" in report
    assert "| ood3 | 0.74 | 26.12 | 0.63 | 114.31 |" in report
    with pytest.raises(SystemExit):
        pe.main(
            ["--out", str(tmp_path), "--report-only", *(str(COMMITTED_SUMMARIES / r) for r in runs[:1] * 2)]
        )
    assert "expected each model once, got 'omnid_seed1002' again" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        pe.main(["--out", str(tmp_path)])
    assert (
        "--train-root and --checkpoint: expected both (or --report-only), got neither"
        in capsys.readouterr().err
    )
