"""Shared ResNet image backbone: images in [0, 1] -> one feature map per image."""

from __future__ import annotations

from pathlib import Path

import torch
import torchvision
from torch import Tensor, nn
from torch.utils.checkpoint import checkpoint

# ImageNet statistics: a fixed normalisation that does not depend on which camera an image comes from.
IMAGENET_MEAN = (0.485, 0.456, 0.406)
IMAGENET_STD = (0.229, 0.224, 0.225)
GROUP_NORM_CHANNELS_PER_GROUP = 16


class ResNetFeatures(nn.Module):
    """torchvision ResNet truncated after ``layer{backbone_layer}``.

    Args:
        name: torchvision constructor name ("resnet18", ..., "resnet101").
        backbone_layer: 2 (stride 8), 3 (stride 16) or 4 (stride 32).
        use_group_norm: GroupNorm instead of BatchNorm.
        weights_path: optional local torchvision state dict (e.g. ImageNet weights saved with
            ``torch.save(model.state_dict(), path)``); nothing is downloaded.
        gradient_checkpointing: in training, keep only each stage's output and recompute the rest in the
            backward pass.
    """

    def __init__(
        self,
        name: str,
        backbone_layer: int,
        use_group_norm: bool,
        weights_path: str | None,
        gradient_checkpointing: bool = False,
    ) -> None:
        super().__init__()
        self.gradient_checkpointing = gradient_checkpointing
        norm_layer = None
        if use_group_norm:
            if weights_path is not None:
                raise ValueError(
                    "`use_group_norm=True` cannot load `pretrained_backbone_weights`: those were trained "
                    "with BatchNorm. Set `use_group_norm=false` to use pretrained weights."
                )

            def norm_layer(channels: int) -> nn.GroupNorm:
                return nn.GroupNorm(channels // GROUP_NORM_CHANNELS_PER_GROUP, channels)

        resnet = getattr(torchvision.models, name)(weights=None, norm_layer=norm_layer)
        if weights_path is not None:
            path = Path(weights_path)
            if not path.is_file():
                raise FileNotFoundError(f"`pretrained_backbone_weights`: no file at {path}")
            state = torch.load(path, map_location="cpu", weights_only=True)
            resnet.load_state_dict(state)
        stages = [resnet.layer1, resnet.layer2, resnet.layer3, resnet.layer4][:backbone_layer]
        self.stem = nn.Sequential(resnet.conv1, resnet.bn1, resnet.relu, resnet.maxpool)
        self.stages = nn.ModuleList(stages)
        last_block = stages[-1][-1]  # BasicBlock ends in conv2, Bottleneck in conv3
        self.out_channels = getattr(last_block, "conv3", last_block.conv2).out_channels
        self.stride = 2 ** (backbone_layer + 1)
        self.register_buffer("mean", torch.tensor(IMAGENET_MEAN).view(1, 3, 1, 1), persistent=False)
        self.register_buffer("std", torch.tensor(IMAGENET_STD).view(1, 3, 1, 1), persistent=False)

    def forward(self, images: Tensor) -> Tensor:
        """(N, 3, H, W) in [0, 1] -> (N, out_channels, ceil(H / stride), ceil(W / stride))."""
        x = (images - self.mean) / self.std
        recompute = self.gradient_checkpointing and self.training and torch.is_grad_enabled()
        for block in (self.stem, *self.stages):
            x = checkpoint(block, x, use_reentrant=False) if recompute else block(x)
        return x
