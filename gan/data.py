"""Image folders as training batches: real chips, renders, both grayscale in [-1, 1].

Every usable image is read once, resized so its shorter side equals `size`, and kept in
memory (N × size² float32: 1000 renders at 256² are 260 MB). Batches are cut from it by
a `Batches` stream whose only randomness is its own torch.Generator, so the data order,
crops and flips are part of a checkpoint and a resumed run sees the same batches as an
uninterrupted one.
"""
from __future__ import annotations

import os
import warnings
from pathlib import Path

import torch

from gan.run import fingerprint
from sasmi.errors import SasmiError
from sasmi.images import list_images, read_gray
from sasmi.preprocess import centre_crop, check_size, resize_short_side, unit_to_signed


class ImageSet:
    """All readable images under `folder` (recursive; a render set's images/ if present).

    Unreadable files are skipped with a warning naming them; a folder with no usable
    image is a SasmiError.
    """

    def __init__(self, folder: str | os.PathLike, size: int):
        check_size(size)
        self.folder = Path(folder)
        self.size = size
        self.paths: list[Path] = []
        self.images: list[torch.Tensor] = []  # each (1, h, w) in [0, 1], min(h, w) == size
        for path in list_images(self.folder):
            try:
                image = read_gray(path)
            except SasmiError as e:
                warnings.warn(f"skipping {e}", stacklevel=2)
                continue
            self.paths.append(path)
            self.images.append(resize_short_side(image, size))
        if not self.images:
            raise SasmiError(f"{self.folder}: no readable image (png, jpg, tif, tiff, npy) in it")

    def __len__(self) -> int:
        return len(self.images)

    def fingerprint(self) -> str:
        """Which files were used: a resumed run must see the same ones."""
        return fingerprint(self.paths, self.folder)

    def center(self, indices: list[int]) -> torch.Tensor:
        """(B, 1, S, S) in [-1, 1], centre-cropped, no augmentation (fixed sample grids)."""
        return unit_to_signed(torch.stack([centre_crop(self.images[i], self.size) for i in indices]))


class Batches:
    """An endless stream of augmented batches from an ImageSet; resumable.

    Each pass visits every image once in a fresh random order. Augmentation is a random
    crop of the longer side and a flip of image y (along-track) only: flipping x would
    put shadows on the wrong side of the target.
    """

    def __init__(self, images: ImageSet, batch: int, seed: int):
        self.images = images
        self.batch = batch
        self.rng = torch.Generator().manual_seed(seed)
        self.order = torch.randperm(len(images), generator=self.rng)
        self.pos = 0

    def _next_index(self) -> int:
        if self.pos == len(self.order):
            self.order = torch.randperm(len(self.images), generator=self.rng)
            self.pos = 0
        self.pos += 1
        return int(self.order[self.pos - 1])

    def next(self) -> torch.Tensor:
        """(B, 1, S, S) in [-1, 1] on the CPU."""
        size = self.images.size
        out = []
        for _ in range(self.batch):
            image = self.images.images[self._next_index()]
            _, h, w = image.shape
            top = int(torch.randint(h - size + 1, (), generator=self.rng))
            left = int(torch.randint(w - size + 1, (), generator=self.rng))
            crop = image[:, top:top + size, left:left + size]
            if torch.rand((), generator=self.rng) < 0.5:
                crop = crop.flip(-2)  # along-track (image y)
            out.append(crop)
        return unit_to_signed(torch.stack(out))

    def state_dict(self) -> dict:
        return {"rng": self.rng.get_state(), "order": self.order.clone(), "pos": self.pos}

    def load_state_dict(self, state: dict) -> None:
        if len(state["order"]) != len(self.images):
            raise SasmiError(f"{self.images.folder}: holds {len(self.images)} usable images but the run was "
                             f"trained on {len(state['order'])}; resume with the same data")
        self.rng.set_state(state["rng"])
        self.order = state["order"].clone()
        self.pos = int(state["pos"])
