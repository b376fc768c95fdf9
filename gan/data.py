"""Image folders as training batches: real chips, renders, both grayscale in [-1, 1].

A render set's masks (masks/NAME.png: 0 seafloor, 1 target, 2 shadow) come along when
asked for, cropped and flipped with their images. Every usable image is read once (by a
DataLoader's worker processes when the set is large), resized so its shorter side equals
`size`, and kept in memory (N × size² float32: 1000 renders at 256² are 260 MB). Batches
are cut from it by a `Batches` stream whose only randomness is its own torch.Generator, so
the data order, crops and flips are part of a checkpoint and a resumed run sees the same
batches as an uninterrupted one.
"""
from __future__ import annotations

import os
import warnings
from pathlib import Path

import torch
import torch.nn.functional as F
from torch.utils.data import DataLoader, Dataset

from sasmi.gan.distributed import check_batch, world
from sasmi.gan.run import fingerprint
from sasmi.errors import SasmiError
from sasmi.images import list_images, read_gray
from sasmi.masks import read_mask
from sasmi.renderset.shards import has_shards, read_shards, shard_files
from sasmi.preprocess import centre_crop, check_size, resize_short_side, unit_to_signed


class ImageSet:
    """All readable images under `folder` (recursive; a render set's images/ if present).

    Unreadable files (and, with masks=True, images without a readable mask) are skipped
    with a warning naming them; a folder with no usable image is a SasmiError.
    """

    def __init__(self, folder: str | os.PathLike, size: int, masks: bool = False):
        check_size(size)
        self.folder = Path(folder)
        self.size = size
        self.paths: list[Path] = []
        self.images: list[torch.Tensor] = []  # each (1, h, w) in [0, 1], min(h, w) == size
        self.masks: list[torch.Tensor] | None = [] if masks else None  # each (1, h, w) uint8 labels
        if has_shards(self.folder):  # a `sasmi render --format wds` set: images (and masks) from its tar shards
            self.images, self.masks = read_shards(self.folder, size, masks)
            self.paths = shard_files(self.folder)  # the fingerprint covers the tar files
            return
        if masks and not (self.folder / "masks").is_dir():
            raise SasmiError(f"{self.folder}: no masks/ folder; the mask loss needs a render set")
        files = _Files(self.folder, list_images(self.folder), size, masks)
        # its own generator: a DataLoader seeds its workers from the global stream, which initialises the weights
        loader = DataLoader(files, batch_size=None, num_workers=reading_workers(len(files)), collate_fn=_as_read,
                            generator=torch.Generator())
        for path, image, mask, error in loader:  # in file order, whatever the workers
            if error:
                warnings.warn(f"skipping {error}", stacklevel=2)
                continue
            self.paths.append(path)
            self.images.append(image)
            if self.masks is not None:
                self.masks.append(mask)
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


def reading_workers(n: int) -> int:
    """Worker processes that decode a set of n files: none for a small set, nor with fewer than 3
    cores (starting them costs more than the ~2 ms per chip they save), else up to 4."""
    workers = min(4, (os.cpu_count() or 1) - 1)
    return workers if n >= 1000 and workers >= 2 else 0


class _Files(Dataset):
    """(path, (1, h, w) in [0, 1], (1, h, w) uint8 mask or None, error or None) per image file."""

    def __init__(self, folder: Path, paths: list[Path], size: int, masks: bool):
        self.folder, self.paths, self.size, self.masks = folder, paths, size, masks

    def __len__(self) -> int:
        return len(self.paths)

    def __getitem__(self, i: int):
        path = self.paths[i]
        try:
            image = resize_short_side(read_gray(path), self.size)
            mask = _read_mask(self.folder, path, image.shape[1:]) if self.masks else None
        except SasmiError as e:  # reported (and skipped) by the reading process, not the worker
            return path, None, None, str(e)
        return path, image, mask, None


def _as_read(item):
    return item


def _read_mask(folder: Path, image_path: Path, shape: tuple[int, int]) -> torch.Tensor:
    """masks/NAME.png of a render set's images/NAME.*, resized (nearest) to `shape`: (1, h, w) uint8."""
    path = (folder / "masks" / image_path.relative_to(folder / "images")).with_suffix(".png")
    mask = torch.from_numpy(read_mask(path))[None, None]  # ids, never palette colours
    return F.interpolate(mask.float(), size=tuple(shape), mode="nearest")[0].to(torch.uint8)


class Batches:
    """An endless stream of augmented batches from an ImageSet; resumable.

    Each pass visits every image once in a fresh random order. Augmentation is a random
    crop of the longer side and a flip of image y (along-track) only: flipping x would
    put shadows on the wrong side of the target.
    """

    def __init__(self, images: ImageSet, batch: int, seed: int):
        check_batch(batch)
        self.images = images
        self.batch = batch  # the global batch: across processes each keeps its slice (gan/distributed.py)
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
        return self.next_with_masks()[0]

    def next_with_masks(self) -> tuple[torch.Tensor, torch.Tensor | None]:
        """(B, 1, S, S) in [-1, 1] and, for a set read with masks, their (B, 1, S, S) uint8 labels;
        B the global batch divided by the number of processes."""
        size, masks = self.images.size, self.images.masks
        out, out_masks = [], []
        for _ in range(self.batch):
            i = self._next_index()
            _, h, w = self.images.images[i].shape
            top = int(torch.randint(h - size + 1, (), generator=self.rng))
            left = int(torch.randint(w - size + 1, (), generator=self.rng))
            flip = bool(torch.rand((), generator=self.rng) < 0.5)  # along-track (image y) only
            for source, sink in ((self.images.images, out), (masks, out_masks)):
                if source is not None:
                    crop = source[i][:, top:top + size, left:left + size]
                    sink.append(crop.flip(-2) if flip else crop)
        local = world().local
        return unit_to_signed(local(torch.stack(out))), local(torch.stack(out_masks)) if masks is not None else None

    def state_dict(self) -> dict:
        return {"rng": self.rng.get_state(), "order": self.order.clone(), "pos": self.pos}

    def load_state_dict(self, state: dict) -> None:
        if len(state["order"]) != len(self.images):
            raise SasmiError(f"{self.images.folder}: holds {len(self.images)} usable images but the run was "
                             f"trained on {len(state['order'])}; resume with the same data")
        self.rng.set_state(state["rng"])
        self.order = state["order"].clone()
        self.pos = int(state["pos"])
