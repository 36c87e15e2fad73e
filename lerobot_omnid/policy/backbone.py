"""Shared ResNet image backbone: images in [0, 1] -> one feature map per image."""

from __future__ import annotations

import re
from collections.abc import Iterable
from pathlib import Path

import torch
import torchvision
from torch import Tensor, nn
from torch.utils.checkpoint import checkpoint
from torchvision.models import WeightsEnum

# ImageNet statistics: a fixed normalisation that does not depend on which camera an image comes from.
IMAGENET_MEAN = (0.485, 0.456, 0.406)
IMAGENET_STD = (0.229, 0.224, 0.225)
GROUP_NORM_CHANNELS_PER_GROUP = 16
# "ResNet18_Weights.IMAGENET1K_V1" (any architecture) or a bare member such as "IMAGENET1K_V1" / "DEFAULT".
_QUALIFIED_WEIGHTS_NAME = re.compile(r"\w+_Weights\.\w+")
_MEMBER_NAME = re.compile(r"[A-Z][A-Z0-9_]*")


def resolve_backbone_weights(name: str, value: str) -> Path | WeightsEnum:
    """What ``pretrained_backbone_weights=value`` means for the torchvision model ``name``.

    As LeRobot's diffusion policy: a torchvision weights name of that model ("ResNet18_Weights.IMAGENET1K_V1",
    or torchvision's short forms "IMAGENET1K_V1" and "DEFAULT"); besides, an existing local state-dict file
    (checked first). Anything else raises an error naming the field, the expected forms and ``value``.
    """
    path = Path(value).expanduser()
    if path.is_file():
        return path
    weights_enum = torchvision.models.get_model_weights(name)
    member = value.removeprefix(f"{weights_enum.__name__}.")
    if member in weights_enum.__members__:
        return weights_enum[member]
    names = ", ".join(f"{weights_enum.__name__}.{m}" for m in weights_enum.__members__)
    expected = f"a local state-dict file or a torchvision weights name for {name} ({names})"
    if _QUALIFIED_WEIGHTS_NAME.fullmatch(value):
        try:
            other = torchvision.models.get_weight(value)
        except (ValueError, KeyError):
            other = None
        if other is not None:
            raise ValueError(
                f"`pretrained_backbone_weights`: {value!r} are weights of another architecture "
                f"({type(other).__name__}) but `vision_backbone` is {name!r}; expected {expected}"
            )
    if _QUALIFIED_WEIGHTS_NAME.fullmatch(value) or _MEMBER_NAME.fullmatch(value):
        raise ValueError(
            f"`pretrained_backbone_weights`: no torchvision weights named {value!r} for {name} (and no file "
            f"of that name); expected {expected}"
        )
    raise FileNotFoundError(
        f"`pretrained_backbone_weights`: no file at {path}, and not a torchvision weights name; "
        f"expected {expected}, got {value!r}"
    )


def download_backbone_weights(name: str, weights: WeightsEnum) -> dict[str, Tensor]:
    """torchvision's state dict for ``weights`` (torch's hub cache, else downloaded); clear error offline."""
    qualified = f"{type(weights).__name__}.{weights.name}"
    try:
        return torch.hub.load_state_dict_from_url(
            weights.url, map_location="cpu", progress=True, check_hash=True
        )
    except OSError as err:  # URLError, socket errors, timeouts
        raise ConnectionError(
            f"`--policy.pretrained_backbone_weights={qualified}`: torchvision could not download these "
            f"weights from {weights.url} ({err}); this machine seems to be offline. Pass a local state-dict "
            f"file instead: on a machine that is online run `torch.save(torchvision.models.{name}("
            f'weights="{qualified}").state_dict(), "{name}_{weights.name.lower()}.pt")`, copy the file here '
            f"and pass `--policy.pretrained_backbone_weights=/path/to/{name}_{weights.name.lower()}.pt`."
        ) from err


def _square(layer: nn.Module, name: str) -> int:
    """A layer's ``kernel_size`` / ``stride`` / ... as one int (AvgPool2d has no dilation: 1)."""
    value = getattr(layer, name, 1)
    pair = value if isinstance(value, tuple) else (value, value)
    if pair[0] != pair[1]:
        raise ValueError(f"feature_cell_centres: expected a square {name}, got {pair} in {layer}")
    return int(pair[0])


def feature_cell_centres(layers: Iterable[nn.Module]) -> tuple[int, float]:
    """Where the cells of a chain of convolutions and poolings sit on its input image.

    Output cell ``j`` of a layer with kernel ``k``, stride ``s``, padding ``p`` and dilation ``d`` is centred
    on input position ``s * j + d * (k - 1) / 2 - p``; composing the layers in order gives the chain's
    ``stride`` and ``offset``: output cell ``j`` is centred on input pixel ``stride * j + offset``, for any
    input size. Layers other than ``Conv2d`` / ``MaxPool2d`` / ``AvgPool2d`` keep positions.

    Returns:
        (stride, offset) in pixels of the input, pixel centres at integers. For torchvision's ResNets
        (``padding = (k - 1) / 2`` throughout) the offset is 0: cell ``j`` is centred on pixel
        ``stride * j``, not on ``(j + 0.5) * stride - 0.5`` as a map spanning the image would have it.
    """
    stride, offset = 1, 0.0
    for layer in layers:
        if not isinstance(layer, nn.Conv2d | nn.MaxPool2d | nn.AvgPool2d):
            continue
        k, s, p, d = (_square(layer, name) for name in ("kernel_size", "stride", "padding", "dilation"))
        offset += stride * (d * (k - 1) / 2 - p)
        stride *= s
    return stride, offset


class ResNetFeatures(nn.Module):
    """torchvision ResNet truncated after ``layer{backbone_layer}``.

    Args:
        name: torchvision constructor name ("resnet18", ..., "resnet101").
        backbone_layer: 1 (stride 4), 2 (stride 8), 3 (stride 16) or 4 (stride 32).
        use_group_norm: GroupNorm instead of BatchNorm.
        weights_path: optional pretrained weights, see :func:`resolve_backbone_weights`: a local
            torchvision state dict (e.g. ImageNet weights saved with ``torch.save(model.state_dict(),
            path)``) or a torchvision weights name such as "ResNet18_Weights.IMAGENET1K_V1" (downloaded
            by torchvision, so only where the machine is online).
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
            source = resolve_backbone_weights(name, weights_path)
            if isinstance(source, Path):
                state = torch.load(source, map_location="cpu", weights_only=True)
            else:
                state = download_backbone_weights(name, source)
            try:
                resnet.load_state_dict(state)
            except RuntimeError as err:
                raise ValueError(
                    f"`pretrained_backbone_weights`: {weights_path!r} is not a state dict of torchvision "
                    f"{name}: {err}"
                ) from err
        stages = [resnet.layer1, resnet.layer2, resnet.layer3, resnet.layer4][:backbone_layer]
        self.stem = nn.Sequential(resnet.conv1, resnet.bn1, resnet.relu, resnet.maxpool)
        self.stages = nn.ModuleList(stages)
        last_block = stages[-1][-1]  # BasicBlock ends in conv2, Bottleneck in conv3
        self.out_channels = getattr(last_block, "conv3", last_block.conv2).out_channels
        # The main path only: a block's downsample shortcut (1x1, stride 2) lands on the same positions.
        main_path = [m for name, m in self.stem.named_modules()] + [
            m for stage in self.stages for name, m in stage.named_modules() if "downsample" not in name
        ]
        self.stride, self.offset = feature_cell_centres(main_path)
        self.register_buffer("mean", torch.tensor(IMAGENET_MEAN).view(1, 3, 1, 1), persistent=False)
        self.register_buffer("std", torch.tensor(IMAGENET_STD).view(1, 3, 1, 1), persistent=False)

    def forward(self, images: Tensor) -> Tensor:
        """(N, 3, H, W) in [0, 1] -> (N, out_channels, ceil(H / stride), ceil(W / stride))."""
        x = (images - self.mean) / self.std
        recompute = self.gradient_checkpointing and self.training and torch.is_grad_enabled()
        for block in (self.stem, *self.stages):
            x = checkpoint(block, x, use_reentrant=False) if recompute else block(x)
        return x
