"""Renders → realistic-looking images with a trained SAS GAN generator.

`translate(generator, images)` is the array form; `translate_folder` mirrors a folder
(or a render set, whose masks/ and labels.jsonl are copied so the labels still apply:
the generator changes texture, not geometry, and keeps the image size).
"""
from __future__ import annotations

import json
import os
import shutil
import warnings
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from tqdm import tqdm

from gan.data import to_signed, to_unit
from sasmi.errors import SasmiError
from sasmi.images import atomic_path, list_images, read_gray, write_gray, write_text


def _resize(x: torch.Tensor, shape: tuple[int, int]) -> torch.Tensor:
    if tuple(x.shape[-2:]) == shape:
        return x
    return F.interpolate(x, size=shape, mode="bilinear", antialias=True, align_corners=False).clamp(0.0, 1.0)


@torch.no_grad()
def translate(generator: torch.nn.Module, images01: np.ndarray, batch: int = 16) -> np.ndarray:
    """(N, H, W) floats in [0, 1] → (N, H, W) float32 in [0, 1].

    Images are resized to the generator's training size and the outputs back to H×W.
    """
    if images01.ndim != 3:
        raise ValueError(f"expected (N, H, W) images, got shape {images01.shape}")
    size = generator.image_size
    device = next(generator.parameters()).device
    out = np.empty(images01.shape, dtype=np.float32)
    for i in range(0, len(images01), batch):
        x = torch.from_numpy(np.ascontiguousarray(images01[i:i + batch], dtype=np.float32))[:, None]
        x = _resize(x.clamp(0.0, 1.0), (size, size))  # (b, 1, S, S) in [0, 1]
        y = to_unit(generator(to_signed(x).to(device)).float().cpu())
        out[i:i + batch] = _resize(y, images01.shape[1:])[:, 0].numpy()
    return out


def translate_folder(generator: torch.nn.Module, in_dir: str | os.PathLike, out_dir: str | os.PathLike,
                     batch: int = 16, provenance: dict | None = None) -> int:
    """Translate every image under in_dir into out_dir as PNG, same relative names; returns the count.

    A render set (in_dir/images/) gives a render set: out_dir/images/, plus masks/ and
    labels.jsonl copied over. Unreadable images are skipped with a warning.
    """
    in_dir, out_dir = Path(in_dir), Path(out_dir)
    paths = list_images(in_dir)
    if not paths:
        raise SasmiError(f"{in_dir}: no image (png, jpg, tif, tiff, npy) in it")
    if out_dir.resolve() == in_dir.resolve() or in_dir.resolve() in out_dir.resolve().parents:
        raise SasmiError(f"--out {out_dir}: must lie outside the input folder {in_dir}")
    render_set = (in_dir / "images").is_dir()
    src_root = in_dir / "images" if render_set else in_dir
    dst_root = out_dir / "images" if render_set else out_dir

    written = 0
    with tqdm(total=len(paths), unit="img", desc="translate", dynamic_ncols=True) as bar:
        for start in range(0, len(paths), batch):
            # read a chunk; images of one shape go through the generator together
            chunk = {}
            for path in paths[start:start + batch]:
                try:
                    chunk[path] = read_gray(path)
                except SasmiError as e:
                    warnings.warn(f"skipping {e}", stacklevel=2)
            for shape in {image.shape for image in chunk.values()}:
                group = [p for p, image in chunk.items() if image.shape == shape]
                outputs = translate(generator, np.stack([chunk[p] for p in group]), batch)
                for path, image in zip(group, outputs):
                    write_gray(dst_root / path.relative_to(src_root).with_suffix(".png"), image)
                    written += 1
            bar.update(len(paths[start:start + batch]))
    if not written:
        raise SasmiError(f"{in_dir}: no readable image in it")

    # carry the labels of a render set over
    if render_set and (in_dir / "masks").is_dir():
        shutil.copytree(in_dir / "masks", out_dir / "masks", dirs_exist_ok=True)
    if render_set and (in_dir / "labels.jsonl").is_file():
        with atomic_path(out_dir / "labels.jsonl") as tmp:
            shutil.copyfile(in_dir / "labels.jsonl", tmp)
    write_text(out_dir / "translate.json", json.dumps(
        {"input": str(in_dir.resolve()), "images": written, **(provenance or {})}, indent=2) + "\n")
    return written
