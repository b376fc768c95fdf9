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
from dataclasses import replace
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
import torch
import torch.nn.functional as F
from tqdm import tqdm

from sasmi.errors import SasmiError
from sasmi.images import TEMPORARIES, FolderLock, check_room, list_images, read_gray, write_gray, write_text
from sasmi.labels import ChipLabel, read_labels
from sasmi.preprocess import resize, signed_to_unit, unit_to_signed

MULTIPLE = 4  # the generator's two stride-2 stages


@torch.no_grad()
def translate(generator: torch.nn.Module, images01: np.ndarray, batch: int = 16,
              seeds: Sequence[int] | None = None) -> np.ndarray:
    """(N, H, W) floats in [0, 1] → (N, H, W) float32 in [0, 1].

    The generator sees what training showed it: each image scaled so its short side is
    the training size S, aspect kept (training centre-crops S×S windows from exactly such
    images; the fully convolutional generator takes the whole of it), reflect-padded to a
    multiple of 4; its output is cropped back and resized to H×W. A generator with a tone style
    (`style_size` > 0) gets one code per image, drawn from a stream seeded by the image's entry of
    `seeds` (default 0, 1, 2, …): one seed, one code, however the images are batched.
    """
    if images01.ndim != 3:
        raise ValueError(f"expected (N, H, W) images, got shape {images01.shape}")
    size = generator.image_size
    device = next(generator.parameters()).device
    h, w = images01.shape[1:]
    scaled = (max(size, round(h * size / min(h, w))), max(size, round(w * size / min(h, w))))
    pad_h, pad_w = -scaled[0] % MULTIPLE, -scaled[1] % MULTIPLE
    out = np.empty(images01.shape, dtype=np.float32)
    style_size = getattr(generator, "style_size", 0)
    seeds = range(len(images01)) if seeds is None else seeds
    assert len(seeds) == len(images01), (len(seeds), len(images01))
    for i in range(0, len(images01), batch):
        x = torch.from_numpy(np.ascontiguousarray(images01[i:i + batch], dtype=np.float32))[:, None]
        x = resize(x.clamp(0.0, 1.0), scaled)  # (b, 1, h', w') in [0, 1], min(h', w') == S
        x = F.pad(unit_to_signed(x), (0, pad_w, 0, pad_h), mode="reflect")  # (b, 1, h'+, w'+) in [-1, 1]
        x = x.to(device, memory_format=torch.channels_last)  # as load_generator lays out the weights
        if style_size:
            code = torch.stack([torch.randn(style_size, generator=torch.Generator().manual_seed(int(seed)))
                                for seed in seeds[i:i + batch]])  # (b, style)
            y = generator(x, code=code.to(device))
        else:
            y = generator(x)
        y = y.float().cpu()[..., :scaled[0], :scaled[1]]
        out[i:i + batch] = resize(signed_to_unit(y), (h, w))[:, 0].numpy()
    return out


def carry_labels(in_dir: Path, out_dir: Path, relabel: Callable[[ChipLabel], ChipLabel] | None = None) -> None:
    """Copy a render set's masks and labels to the set of its chips remade as PNGs in out_dir/images/:
    the chips keep their geometry, so the labels still apply, but for what `relabel` changes."""
    for masks in ("masks", "instances", "shadows"):  # class, instance and shadow-instance masks
        if (in_dir / masks).is_dir():
            shutil.copytree(in_dir / masks, out_dir / masks, dirs_exist_ok=True)
    if (in_dir / "labels.jsonl").is_file():
        # the new chips are PNGs whatever the renders were (tiff16, npy): point the labels at them
        labels = [replace(label, image=str(Path(label.image).with_suffix(".png")) if label.image else label.image)
                  for label in read_labels(in_dir)]
        if relabel is not None:
            labels = [relabel(label) for label in labels]
        write_text(out_dir / "labels.jsonl", "".join(label.dumps() + "\n" for label in labels))


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
    # a translated chip takes about the room of its render (8-bit PNG either way; larger renders, less); a
    # rerun rewrites the chips already there in place
    src_root, dst_root = _roots(in_dir, out_dir)
    todo = [p for p in paths if not (dst_root / p.relative_to(src_root)).with_suffix(".png").is_file()]
    check_room(out_dir, sum(p.stat().st_size for p in todo), f"{len(todo)} translated chips")
    lock = FolderLock(out_dir, "translating")  # two generators into one folder would mix their chips
    try:
        # a killed translation leaves the file it was writing as a hidden temporary;
        # under the lock no one else writes here, so each is a leftover
        for leftover in out_dir.rglob(TEMPORARIES):
            leftover.unlink(missing_ok=True)
        written = _translate_all(generator, paths, in_dir, out_dir, batch)
        write_text(out_dir / "translate.json", json.dumps(
            {"input": str(in_dir.resolve()), "images": written, **(provenance or {})}, indent=2) + "\n")
    finally:
        lock.release()
    return written


def _roots(in_dir: Path, out_dir: Path) -> tuple[Path, Path]:
    """Where the images lie in and go to: images/ of a render set, else the folders themselves."""
    render_set = (in_dir / "images").is_dir()
    return (in_dir / "images", out_dir / "images") if render_set else (in_dir, out_dir)


def _translate_all(generator: torch.nn.Module, paths: list[Path], in_dir: Path, out_dir: Path, batch: int) -> int:
    render_set = (in_dir / "images").is_dir()
    src_root, dst_root = _roots(in_dir, out_dir)

    written, place = 0, {path: i for i, path in enumerate(paths)}
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
                # each file's place in the folder seeds its tone-style code
                outputs = translate(generator, np.stack([chunk[p] for p in group]), batch,
                                    seeds=[place[p] for p in group])
                for path, image in zip(group, outputs):
                    write_gray(dst_root / path.relative_to(src_root).with_suffix(".png"), image)
                    written += 1
            bar.update(len(paths[start:start + batch]))
    if not written:
        raise SasmiError(f"{in_dir}: no readable image in it")

    if render_set:
        carry_labels(in_dir, out_dir)
    return written
