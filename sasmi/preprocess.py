"""The one image -> tensor path: read, gray, short side to size, centre crop, value range.

Value ranges have one name each, used everywhere:
- *unit*: float in [0, 1]: files on disk, numpy arrays, metrics, plots.
- *signed*: float in [-1, 1]: what every network takes and returns.

Training, translation, evaluation and the datasets all call `fit_image` (or
`load_image`), so a network sees at inference exactly the crop it saw in training.
"""
from __future__ import annotations

import os
from typing import TYPE_CHECKING

import numpy as np

from sasmi.errors import SasmiError
from sasmi.images import read_gray
from sasmi.limits import FLAGS

if TYPE_CHECKING:  # torch is imported where a tensor is made: `sasmi render` needs none (and 180 MB less)
    import torch


def check_size(size: int, flag: str = "--size") -> int:
    """`size` if it lies in the range of --size (limits.FLAGS), else a SasmiError naming `flag`."""
    if isinstance(size, bool) or not isinstance(size, (int, np.integer)):
        raise SasmiError(f"{flag} {size!r}: is not a whole number")
    return FLAGS["--size"].check(int(size), flag)


def unit_to_signed(x01: torch.Tensor) -> torch.Tensor:
    """[0, 1] -> [-1, 1]."""
    return x01 * 2.0 - 1.0


def signed_to_unit(x: torch.Tensor) -> torch.Tensor:
    """[-1, 1] -> [0, 1], clamped (network outputs may overshoot)."""
    return ((x + 1.0) * 0.5).clamp(0.0, 1.0)


def resize_short_side(image01: np.ndarray, size: int) -> torch.Tensor:
    """(H, W) in [0, 1] -> (1, h, w) in [0, 1] with min(h, w) == size; antialiased when shrinking."""
    import torch
    import torch.nn.functional as F

    h, w = image01.shape
    scale = size / min(h, w)
    shape = (max(size, round(h * scale)), max(size, round(w * scale)))
    x = torch.from_numpy(np.ascontiguousarray(image01, dtype=np.float32))[None, None]
    if shape != (h, w):
        x = F.interpolate(x, size=shape, mode="bilinear", antialias=True, align_corners=False)
    return x[0].clamp(0.0, 1.0)


def resize(x01: torch.Tensor, shape: tuple[int, int]) -> torch.Tensor:
    """(B, C, h, w) in [0, 1] -> (B, C, *shape) in [0, 1]; the identity when the shape matches."""
    import torch.nn.functional as F

    if tuple(x01.shape[-2:]) == tuple(shape):
        return x01
    return F.interpolate(x01, size=tuple(shape), mode="bilinear", antialias=True, align_corners=False).clamp(0, 1)


def crop_box(shape: tuple[int, int], size: int) -> tuple[int, int]:
    """(top, left) of the centred size x size crop of an image of `shape` (both sides >= size)."""
    return (shape[0] - size) // 2, (shape[1] - size) // 2


def centre_crop(x: torch.Tensor, size: int) -> torch.Tensor:
    """(..., h, w) -> (..., size, size), centred."""
    top, left = crop_box(tuple(x.shape[-2:]), size)
    return x[..., top:top + size, left:left + size]


def fit_image(image01: np.ndarray, size: int) -> np.ndarray:
    """(H, W) in [0, 1] -> (size, size) float32 in [0, 1]: short side to `size`, centre crop."""
    return centre_crop(resize_short_side(image01, size)[0], size).numpy()


def load_image(path: str | os.PathLike, size: int) -> np.ndarray:
    """A file -> (size, size) float32 in [0, 1]; SasmiError naming the file if unreadable."""
    return fit_image(read_gray(path), size)


def to_batch(images01: np.ndarray, device: torch.device | str = "cpu") -> torch.Tensor:
    """(N, S, S) in [0, 1] (numpy) -> (N, 1, S, S) in [-1, 1] on `device`: what networks take."""
    import torch

    if images01.ndim != 3:
        raise ValueError(f"expected (N, H, W) images, got shape {images01.shape}")
    x = torch.from_numpy(np.ascontiguousarray(images01, dtype=np.float32))[:, None]
    return unit_to_signed(x).to(device)
