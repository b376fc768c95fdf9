"""Torch datasets for ATR work: render sets in torchvision's detection convention, and real chip folders.

    from sasmi.atr.datasets import RenderSet, RealChips
    image, target = RenderSet("runs/renders")[0]   # (1, H, W) in [0, 1], dict of tensors
    image, label = RealChips("chips", size=128)[0]  # (1, 128, 128) in [0, 1], class index

Both keep only file paths and read in `__getitem__`, so `DataLoader(num_workers=N)` works.
"""
from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import torch

from sasmi.errors import SasmiError
from sasmi.images import list_images, read_gray
from sasmi.labels import ChipLabel, categories_of, read_labels
from sasmi.masks import read_mask
from sasmi.preprocess import fit_image


def render_set_categories(folder: str | os.PathLike, labels: list[ChipLabel] | None = None) -> list[str]:
    """Class names in id order (id = position + 1): run.json's list, else derived from the labels."""
    run = Path(folder) / "run.json"
    if run.is_file():
        try:
            names = json.loads(run.read_text()).get("categories")
        except (OSError, json.JSONDecodeError) as e:
            raise SasmiError(f"{run}: cannot read ({e})") from None
        if names:
            return list(names)
    return categories_of(labels if labels is not None else read_labels(folder))


class RenderSet(torch.utils.data.Dataset):
    """A render set (or its translation) as (image, target) pairs for detection and segmentation.

    image: (1, H, W) float32 in [0, 1]. target (torchvision's detection convention):
      boxes (N, 4) float32 xyxy in pixels, labels (N,) int64 class ids (1-based, see
      `categories`), masks (N, H, W) uint8 instance masks, shadow_masks (N, H, W) uint8
      (shadow n belongs to target n), class_mask (H, W) int64 (0 seafloor, 1 target,
      2 shadow), companion (N,) bool (another object in view, not the contact the chip
      is cut around: `sasmi.scene.model.Target.role`), image_id int64, and `scene` (the sampled
      parameters, a dict).
    Targets the camera cannot see (fully buried or hidden) have no box and are left out
    of the tensors; they stay in `scene`.
    """

    def __init__(self, folder: str | os.PathLike):
        self.folder = Path(folder)
        self.labels = read_labels(self.folder)
        if not self.labels:
            raise SasmiError(f"{self.folder}: labels.jsonl holds no chip")
        for sub in ("instances", "shadows"):
            if not (self.folder / sub).is_dir():
                raise SasmiError(f"{self.folder}: no {sub}/ folder (a render set from an older sasmi: render it again)")
        self.categories = render_set_categories(self.folder, self.labels)
        self._ids = {name: i + 1 for i, name in enumerate(self.categories)}
        self._images = {int(p.stem): p for p in list_images(self.folder) if p.stem.isdigit()}
        missing = [label.index for label in self.labels if label.index not in self._images]
        if missing:
            raise SasmiError(f"{self.folder}: no image for chip {missing[0]} ({len(missing)} missing)")

    def __len__(self) -> int:
        return len(self.labels)

    def image_path(self, i: int) -> Path:
        return self._images[self.labels[i].index]

    def __getitem__(self, i: int) -> tuple[torch.Tensor, dict]:
        label = self.labels[i]
        name = f"{label.index:06d}.png"
        image = read_gray(self._images[label.index])  # (H, W) in [0, 1]
        instances = read_mask(self.folder / "instances" / name)
        shadows = read_mask(self.folder / "shadows" / name)
        classes = read_mask(self.folder / "masks" / name)
        if not image.shape == instances.shape == shadows.shape == classes.shape:
            raise SasmiError(f"{self.folder}: chip {label.index}: image {image.shape} and masks differ in size")
        shown = [k for k, t in enumerate(label.targets) if t.bbox is not None]
        h, w = image.shape
        return torch.from_numpy(image)[None], {
            "boxes": torch.tensor([label.targets[k].bbox for k in shown], dtype=torch.float32).reshape(-1, 4),
            "labels": torch.tensor([self._ids[label.targets[k].category] for k in shown], dtype=torch.int64),
            "masks": torch.from_numpy(np.stack([instances == k + 1 for k in shown]).astype(np.uint8)
                                      if shown else np.zeros((0, h, w), np.uint8)),
            "shadow_masks": torch.from_numpy(np.stack([shadows == k + 1 for k in shown]).astype(np.uint8)
                                             if shown else np.zeros((0, h, w), np.uint8)),
            "class_mask": torch.from_numpy(classes.astype(np.int64)),
            "companion": torch.tensor([label.targets[k].role == "companion" for k in shown], dtype=torch.bool),
            "image_id": torch.tensor(label.index, dtype=torch.int64),
            "scene": {**label.scene, "targets": [t.to_json() for t in label.targets]},
        }


class RealChips(torch.utils.data.Dataset):
    """A folder of real chips as (image (1, S, S) in [0, 1], class index).

    With subfolders (e.g. targets/ and seafloor/) each subfolder is a class, in sorted
    order (`classes`); a flat folder is one class, 0. Images are brought to `size` by the
    project's one preprocessing path (short side to size, centre crop); with size=None
    they keep their own size (then batch only chips of one size).
    """

    def __init__(self, folder: str | os.PathLike, size: int | None = 128):
        self.folder = Path(folder)
        self.size = size
        subfolders = sorted(p for p in self.folder.iterdir() if p.is_dir() and list_images(p)) \
            if self.folder.is_dir() else []
        if subfolders:
            self.classes = [p.name for p in subfolders]
            self.items = [(path, c) for c, sub in enumerate(subfolders) for path in list_images(sub)]
        else:
            self.classes = [self.folder.name]
            self.items = [(path, 0) for path in list_images(self.folder)]
        if not self.items:
            raise SasmiError(f"{self.folder}: no image (png, jpg, tif, tiff, npy) in it")

    def __len__(self) -> int:
        return len(self.items)

    def __getitem__(self, i: int) -> tuple[torch.Tensor, int]:
        path, label = self.items[i]
        image = read_gray(path)
        if self.size is not None:
            image = fit_image(image, self.size)
        return torch.from_numpy(np.ascontiguousarray(image, dtype=np.float32))[None], label


def detection_collate(batch: list) -> tuple[list, list]:
    """For DataLoader(collate_fn=...): detection targets differ in N, so keep lists, as torchvision does."""
    images, targets = zip(*batch)
    return list(images), list(targets)
