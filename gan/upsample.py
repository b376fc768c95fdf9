"""Nearest ×2 upsampling and the 3×3 conv after it, computed at the low resolution.

Each output pixel of [repeat every pixel 2×2 → 3×3 conv] sees only 2×2 distinct input
pixels, so each of the four output phases (row and column parity) is a 2×2 conv of the
low-resolution image whose taps are sums of the 3×3 taps. A reflect or replicate padding of
1 px around the upsampled image repeats the low-resolution image's edge pixels, so the
phases read a replicate-padded input. Four 2×2 convs spend 16 taps where the 3×3 conv on the
upsampled image spends 36, and the upsampled image is never made: the same outputs to float
rounding, and the shipped generator's translation of a chip in about 0.86 × the time
(benchmarks/translate_speed.py, docs/results.md).
"""
from __future__ import annotations

import torch
import torch.nn as nn
import torch.nn.functional as F


def _fold(taps: torch.Tensor) -> torch.Tensor:
    """(..., 3) taps over the upsampled axis → (2, ..., 2): per output phase, the taps on the
    low-resolution pixels (i-1, i) for an even output row, (i, i+1) for an odd one."""
    even = torch.stack([taps[..., 0], taps[..., 1] + taps[..., 2]], -1)
    odd = torch.stack([taps[..., 0] + taps[..., 1], taps[..., 2]], -1)
    return torch.stack([even, odd])


def foldable(up: nn.Module, conv: nn.Module) -> bool:
    """Whether (up, conv) is a nearest ×2 upsampling and a 3×3 conv that NearestUpConv computes."""
    return (isinstance(up, nn.Upsample) and up.mode == "nearest" and up.size is None
            and up.scale_factor in (2, 2.0, (2, 2), (2.0, 2.0))
            and type(conv) is nn.Conv2d and conv.kernel_size == (3, 3) and conv.stride == (1, 1)
            and conv.padding == (1, 1) and conv.dilation == (1, 1) and conv.groups == 1
            and conv.padding_mode in ("reflect", "replicate"))


class NearestUpConv(nn.Module):
    """conv(nearest ×2 upsampling of x) for a 3×3, stride-1, 1-px reflect- or replicate-padded
    `conv`, whose parameters it holds under their own names (a net's state_dict is unchanged)."""

    def __init__(self, conv: nn.Conv2d):
        super().__init__()
        if not foldable(nn.Upsample(scale_factor=2, mode="nearest"), conv):
            raise ValueError(f"NearestUpConv: {conv} is not a 3×3, stride-1, 1-px reflect- or replicate-padded conv")
        self.weight, self.bias, self.padding_mode = conv.weight, conv.bias, conv.padding_mode

    def forward(self, x: torch.Tensor) -> torch.Tensor:  # (B, I, H, W) → (B, O, 2H, 2W), channels last
        rows = _fold(self.weight.transpose(-1, -2)).transpose(-1, -2)  # (row phase, O, I, 2, 3)
        kernels = _fold(rows)  # (column phase, row phase, O, I, 2, 2)
        (b, _, h, w), o = x.shape, self.weight.shape[0]
        padded = F.pad(x, (1, 1, 1, 1), mode="replicate")
        out = x.new_empty(b, h, 2, w, 2, o)
        for row in (0, 1):
            for col in (0, 1):
                phase = F.conv2d(padded[..., row:row + h + 1, col:col + w + 1], kernels[col, row], self.bias)
                out[:, :, row, :, col] = phase.permute(0, 2, 3, 1)
        return out.view(b, 2 * h, 2 * w, o).permute(0, 3, 1, 2)

    def unfolded(self) -> nn.Sequential:
        """The plain [nearest ×2 upsampling, 3×3 conv] layers it computes, sharing its parameters."""
        o, i = self.weight.shape[:2]
        conv = nn.Conv2d(i, o, 3, padding=1, padding_mode=self.padding_mode, bias=self.bias is not None)
        conv.weight, conv.bias = self.weight, self.bias
        return nn.Sequential(nn.Upsample(scale_factor=2, mode="nearest"), conv)


def fold_upsampling(net: nn.Sequential) -> nn.Sequential:
    """`net` with each [nearest ×2 upsampling, 3×3 conv] pair of its layers computed at the low
    resolution (NearestUpConv, holding the conv's parameters; the upsampling becomes an Identity, so
    every layer keeps its index and the state_dict its keys). In place; returns `net`."""
    for i in range(len(net) - 1):
        if foldable(net[i], net[i + 1]):
            net[i], net[i + 1] = nn.Identity(), NearestUpConv(net[i + 1])
    return net
