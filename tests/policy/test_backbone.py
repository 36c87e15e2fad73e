"""The shared ResNet backbone: stride and channels of each usable stage, the config's check, and its
pretrained weights (local files and torchvision weights names, offline: nothing is downloaded)."""

import math
import urllib.error

import pytest
import torch
import torchvision
from omnid_testing import tiny_config
from torchvision.models import ResNet18_Weights

from lerobot_omnid.policy.backbone import ResNetFeatures


@pytest.mark.parametrize(
    ("layer", "stride", "channels"), [(1, 4, 64), (2, 8, 128), (3, 16, 256), (4, 32, 512)]
)
def test_feature_map_stride_and_channels(layer, stride, channels):
    backbone = ResNetFeatures("resnet18", layer, use_group_norm=True, weights_path=None)
    features = backbone(torch.rand(2, 3, 64, 48))
    assert (backbone.stride, backbone.out_channels) == (stride, channels)
    assert features.shape == (2, channels, math.ceil(64 / stride), math.ceil(48 / stride))


@pytest.mark.parametrize("layer", [0, 5])
def test_config_rejects_other_stages(layer):
    with pytest.raises(ValueError, match=rf"`backbone_layer`: expected one of \[1, 2, 3, 4\], got {layer}"):
        tiny_config(backbone_layer=layer)


@pytest.fixture(autouse=True)
def offline(monkeypatch):
    """Tests never download: torchvision's weights would come through torch.hub, which fails here."""

    def fail(url, *args, **kwargs):
        raise urllib.error.URLError(f"offline test: no download of {url}")

    monkeypatch.setattr(torch.hub, "load_state_dict_from_url", fail)


def assert_weights_equal(backbone: ResNetFeatures, reference: dict[str, torch.Tensor]) -> None:
    """Every tensor of the truncated backbone equals the reference's (torchvision naming)."""
    renamed = {"stem.0.": "conv1.", "stem.1.": "bn1."} | {f"stages.{i}.": f"layer{i + 1}." for i in range(4)}
    state = backbone.state_dict()
    assert state
    for key, value in state.items():
        prefix = next(p for p in renamed if key.startswith(p))
        assert torch.equal(value, reference[renamed[prefix] + key.removeprefix(prefix)]), key


def test_loads_a_local_state_dict_file(tmp_path):
    reference = torchvision.models.resnet18(weights=None).state_dict()
    path = tmp_path / "resnet18.pt"
    torch.save(reference, path)
    assert_weights_equal(
        ResNetFeatures("resnet18", 4, use_group_norm=False, weights_path=str(path)), reference
    )


@pytest.mark.parametrize("value", ["ResNet18_Weights.IMAGENET1K_V1", "IMAGENET1K_V1", "DEFAULT"])
def test_loads_a_torchvision_weights_name_through_torch_hub(monkeypatch, value):
    reference = torchvision.models.resnet18(weights=None).state_dict()
    urls = []

    def serve(url, *args, **kwargs):
        urls.append(url)
        return reference

    monkeypatch.setattr(torch.hub, "load_state_dict_from_url", serve)
    backbone = ResNetFeatures("resnet18", 3, use_group_norm=False, weights_path=value)
    assert urls == [ResNet18_Weights.IMAGENET1K_V1.url]
    assert_weights_equal(backbone, reference)


def test_weights_name_offline_says_to_pass_a_local_file():
    with pytest.raises(ConnectionError) as caught:
        ResNetFeatures("resnet18", 4, use_group_norm=False, weights_path="ResNet18_Weights.IMAGENET1K_V1")
    message = str(caught.value)
    assert "`--policy.pretrained_backbone_weights=ResNet18_Weights.IMAGENET1K_V1`" in message
    assert "Pass a local state-dict file instead" in message
    assert 'torch.save(torchvision.models.resnet18(weights="ResNet18_Weights.IMAGENET1K_V1")' in message
    assert isinstance(caught.value.__cause__, urllib.error.URLError)


def test_unknown_weights_name_lists_the_expected_forms():
    with pytest.raises(ValueError) as caught:
        ResNetFeatures("resnet18", 4, use_group_norm=False, weights_path="ResNet18_Weights.IMAGENET9K")
    message = str(caught.value)
    assert message.startswith("`pretrained_backbone_weights`: no torchvision weights named")
    assert "'ResNet18_Weights.IMAGENET9K'" in message
    assert "a local state-dict file or a torchvision weights name for resnet18" in message
    assert "ResNet18_Weights.IMAGENET1K_V1, ResNet18_Weights.DEFAULT" in message


def test_weights_name_of_another_architecture_is_rejected():
    with pytest.raises(
        ValueError, match=r"another architecture \(ResNet50_Weights\) but `vision_backbone` is "
    ):
        ResNetFeatures("resnet18", 4, use_group_norm=False, weights_path="ResNet50_Weights.IMAGENET1K_V2")


def test_missing_file_names_the_field_and_the_expected_forms(tmp_path):
    missing = tmp_path / "resnet18.pt"
    with pytest.raises(FileNotFoundError) as caught:
        ResNetFeatures("resnet18", 4, use_group_norm=False, weights_path=str(missing))
    message = str(caught.value)
    assert message.startswith(f"`pretrained_backbone_weights`: no file at {missing}")
    assert f"got {str(missing)!r}" in message and "ResNet18_Weights.IMAGENET1K_V1" in message


def test_state_dict_of_another_architecture_is_rejected(tmp_path):
    path = tmp_path / "resnet34.pt"
    torch.save(torchvision.models.resnet34(weights=None).state_dict(), path)
    with pytest.raises(ValueError, match="is not a state dict of torchvision resnet18"):
        ResNetFeatures("resnet18", 4, use_group_norm=False, weights_path=str(path))


def test_group_norm_refuses_pretrained_weights_before_any_download():
    with pytest.raises(ValueError, match="`use_group_norm=True` cannot load `pretrained_backbone_weights`"):
        ResNetFeatures("resnet18", 4, use_group_norm=True, weights_path="ResNet18_Weights.IMAGENET1K_V1")


@pytest.mark.parametrize("layer", [1, 2, 3, 4])
def test_feature_cells_sit_where_feature_cell_centres_says(layer):
    """The gradient centroid of a feature cell (BatchNorm backbone in eval mode, so each cell depends only on
    its receptive field) is at pixel ``stride * j + offset``, not at ``(j + 0.5) * stride - 0.5``. The image
    (257 px, not a multiple of any stride) is centred on the cell, so the receptive field is cut evenly."""
    backbone = ResNetFeatures("resnet18", layer, use_group_norm=False, weights_path=None).eval()
    size = 257
    j = 128 // backbone.stride
    images = torch.rand(1, 3, size, size, requires_grad=True)
    backbone(images)[0, :, j, j].sum().backward()
    weight = images.grad.abs().sum(dim=(0, 1))
    weight = weight / weight.sum()
    pixels = torch.arange(size, dtype=torch.float32)
    centroid = torch.stack([(weight.sum(0) * pixels).sum(), (weight.sum(1) * pixels).sum()])
    expected = backbone.stride * j + backbone.offset
    assert backbone.offset == 0.0
    assert torch.allclose(centroid, torch.tensor([expected, expected]), atol=1.5)
    spanning_the_image = (j + 0.5) * backbone.stride - 0.5  # where grid_sample over the image puts it
    assert (centroid - spanning_the_image).abs().min() > (backbone.stride - 1) / 2 - 1.5
