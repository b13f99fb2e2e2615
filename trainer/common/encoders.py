"""Observation encoders: vector (identity + optional normaliser) and visual CHW encoders.

Visual encoders take float [n, C, H, W] in [0, 1] and return [n, hidden_units]. Their dense output
layer is Kaiming-normal with gain 1.41 (a ReLU gain), as in ML-Agents.
"""
from __future__ import annotations

import torch
from torch import nn

from trainer.config.settings import ENCODER_MIN_SIZE
from trainer.errors import ConfigError
from trainer.common.layers import KAIMING_NORMAL, Swish, linear_layer
from trainer.common.normalizer import Normalizer

RELU_GAIN = 1.41


def conv_output_hw(hw: tuple[int, int], kernel: int, stride: int = 1, padding: int = 0) -> tuple[int, int]:
    """Height and width after a Conv2d with square kernel."""
    return tuple((d + 2 * padding - kernel) // stride + 1 for d in hw)  # type: ignore[return-value]


def _dense(flat_size: int, output_size: int) -> nn.Sequential:
    return nn.Sequential(linear_layer(flat_size, output_size, KAIMING_NORMAL, RELU_GAIN), nn.LeakyReLU())


class _ConvStackEncoder(nn.Module):
    """Conv layers (each followed by LeakyReLU) -> flatten -> Linear -> LeakyReLU."""

    def __init__(self, shape: tuple[int, int, int], output_size: int, convs: list[tuple[int, int, int]]):
        super().__init__()
        channels, hw = shape[0], (shape[1], shape[2])
        layers: list[nn.Module] = []
        for out_channels, kernel, stride in convs:
            layers += [nn.Conv2d(channels, out_channels, kernel, stride), nn.LeakyReLU()]
            channels, hw = out_channels, conv_output_hw(hw, kernel, stride)
        self.final_flat = channels * hw[0] * hw[1]
        self.conv_layers = nn.Sequential(*layers)
        self.dense = _dense(self.final_flat, output_size)

    def forward(self, visual_obs: torch.Tensor) -> torch.Tensor:
        hidden = self.conv_layers(visual_obs)
        return self.dense(hidden.reshape(-1, self.final_flat))


class SimpleVisualEncoder(_ConvStackEncoder):
    """Conv(16, 8x8, s4) -> Conv(32, 4x4, s2) -> Linear(h). Needs H, W >= 20."""

    def __init__(self, shape: tuple[int, int, int], output_size: int):
        super().__init__(shape, output_size, [(16, 8, 4), (32, 4, 2)])


class NatureVisualEncoder(_ConvStackEncoder):
    """Conv(32, 8x8, s4) -> Conv(64, 4x4, s2) -> Conv(64, 3x3, s1) -> Linear(h). Needs H, W >= 36."""

    def __init__(self, shape: tuple[int, int, int], output_size: int):
        super().__init__(shape, output_size, [(32, 8, 4), (64, 4, 2), (64, 3, 1)])


class SmallVisualEncoder(_ConvStackEncoder):
    """``match3``: Conv(35, 3x3) -> Conv(144, 3x3) -> Linear(h), for tiny grids. Needs H, W >= 5."""

    def __init__(self, shape: tuple[int, int, int], output_size: int):
        super().__init__(shape, output_size, [(35, 3, 1), (144, 3, 1)])


class FullyConnectedVisualEncoder(nn.Module):
    """Flatten -> Linear(h) -> LeakyReLU."""

    def __init__(self, shape: tuple[int, int, int], output_size: int):
        super().__init__()
        self.input_size = shape[0] * shape[1] * shape[2]
        self.dense = _dense(self.input_size, output_size)

    def forward(self, visual_obs: torch.Tensor) -> torch.Tensor:
        return self.dense(visual_obs.reshape(-1, self.input_size))


class _ResNetBlock(nn.Module):
    def __init__(self, channels: int):
        super().__init__()
        self.layers = nn.Sequential(
            Swish(), nn.Conv2d(channels, channels, 3, 1, padding=1),
            Swish(), nn.Conv2d(channels, channels, 3, 1, padding=1),
        )

    def forward(self, inputs: torch.Tensor) -> torch.Tensor:
        return inputs + self.layers(inputs)


class ResNetVisualEncoder(nn.Module):
    """Three stacks (16, 32, 32 channels) of Conv -> MaxPool(3, s2) -> 2 residual blocks; Swish; Linear; ReLU."""

    def __init__(self, shape: tuple[int, int, int], output_size: int):
        super().__init__()
        channels, (height, width) = shape[0], (shape[1], shape[2])
        layers: list[nn.Module] = []
        for out_channels in (16, 32, 32):
            layers += [nn.Conv2d(channels, out_channels, 3, 1, padding=1), nn.MaxPool2d(3, 2)]
            height, width = (height - 3) // 2 + 1, (width - 3) // 2 + 1
            layers += [_ResNetBlock(out_channels), _ResNetBlock(out_channels)]
            channels = out_channels
        layers.append(Swish())
        self.sequential = nn.Sequential(*layers)
        self.final_flat = channels * height * width
        self.dense = linear_layer(self.final_flat, output_size, KAIMING_NORMAL, RELU_GAIN)

    def forward(self, visual_obs: torch.Tensor) -> torch.Tensor:
        hidden = self.sequential(visual_obs).reshape(-1, self.final_flat)
        return torch.relu(self.dense(hidden))


# vis_encode_type -> (encoder class, minimum height/width: trainer.config.settings.ENCODER_MIN_SIZE)
VISUAL_ENCODERS: dict[str, tuple[type[nn.Module], int]] = {
    name: (encoder, ENCODER_MIN_SIZE[name]) for name, encoder in (
        ("simple", SimpleVisualEncoder), ("nature_cnn", NatureVisualEncoder), ("resnet", ResNetVisualEncoder),
        ("match3", SmallVisualEncoder), ("fully_connected", FullyConnectedVisualEncoder))
}


def make_visual_encoder(shape: tuple[int, ...], output_size: int, vis_encode_type: str) -> nn.Module:
    """Build the encoder for one CHW observation, with a clear ConfigError for bad type or size."""
    if vis_encode_type not in VISUAL_ENCODERS:
        raise ConfigError(
            f"network_settings.vis_encode_type {vis_encode_type!r} is not supported; "
            f"use one of {sorted(VISUAL_ENCODERS)}"
        )
    encoder_class, min_size = VISUAL_ENCODERS[vis_encode_type]
    if min(shape[1], shape[2]) < min_size:
        raise ConfigError(
            f"a visual observation of shape {tuple(shape)} (C, H, W) is too small for "
            f"vis_encode_type {vis_encode_type!r}, which needs height and width >= {min_size}; "
            "use a larger camera resolution or another vis_encode_type (e.g. match3 or fully_connected)"
        )
    return encoder_class(tuple(shape), output_size)


class VectorInput(nn.Module):
    """Identity on [n, size], or the running normaliser when ``normalize`` is set."""

    def __init__(self, size: int, normalize: bool):
        super().__init__()
        self.normalizer = Normalizer(size) if normalize else None

    def forward(self, inputs: torch.Tensor) -> torch.Tensor:
        return self.normalizer(inputs) if self.normalizer is not None else inputs

    def update_normalization(self, inputs: torch.Tensor) -> None:
        if self.normalizer is not None:
            self.normalizer.update(inputs)
