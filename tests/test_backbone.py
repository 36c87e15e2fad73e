"""The shared ResNet backbone: stride and channels of each usable stage, and the config's check."""

import math

import pytest
import torch
from omnid_testing import tiny_config

from lerobot_omnid.policy.backbone import ResNetFeatures


@pytest.mark.parametrize(("layer", "stride", "channels"), [(2, 8, 128), (3, 16, 256), (4, 32, 512)])
def test_feature_map_stride_and_channels(layer, stride, channels):
    backbone = ResNetFeatures("resnet18", layer, use_group_norm=True, weights_path=None)
    features = backbone(torch.rand(2, 3, 64, 48))
    assert (backbone.stride, backbone.out_channels) == (stride, channels)
    assert features.shape == (2, channels, math.ceil(64 / stride), math.ceil(48 / stride))


@pytest.mark.parametrize("layer", [1, 5])
def test_config_rejects_other_stages(layer):
    with pytest.raises(ValueError, match=rf"`backbone_layer` must be one of \[2, 3, 4\], got {layer}"):
        tiny_config(backbone_layer=layer)
