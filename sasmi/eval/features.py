"""Images and their φ features: the input of every metric.

φ is the 1024-d code of the GAN's autoencoder (`sasmi.gan.autoencoder.load_encoder`). Images go
through `sasmi.preprocess.load_image` (short side to the encoder's size, centre crop),
the same path as training, so the encoder sees what it was trained on. A set is read a block at
a time: φ from the float images, then kept as 8-bit pixels (for nearest neighbours and figures),
so 20000 chips at 128² hold 330 MB, not 1.3 GB.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
from tqdm import tqdm

from sasmi.errors import SasmiError
from sasmi.eval import cache
from sasmi.images import list_images


@dataclass(frozen=True)
class FeatureSet:
    name: str
    folder: Path
    images: np.ndarray  # (N, S, S) uint8: what the encoder saw, times 255, rounded
    phi: np.ndarray  # (N, D) float64
    names: tuple[str, ...] = ()  # file names, in row order; empty for sets made in memory

    def __post_init__(self):
        assert self.images.dtype == np.uint8 and self.images.ndim == 3, (self.images.dtype, self.images.shape)
        assert self.phi.ndim == 2 and len(self.phi) == len(self.images), (self.phi.shape, self.images.shape)
        assert not self.names or len(self.names) == len(self.phi), (len(self.names), self.phi.shape)

    def name_of(self, i: int) -> str:
        return self.names[i] if self.names else f"#{i}"

    def image(self, i: int) -> np.ndarray:
        """(S, S) float32 in [0, 1]."""
        return self.images[i].astype(np.float32) / 255.0


def to_pixels(images: np.ndarray) -> np.ndarray:
    """(N, S, S) in [0, 1] → uint8, as FeatureSet keeps them."""
    return np.round(np.clip(images, 0.0, 1.0) * 255.0).astype(np.uint8)


def as_encoder(phi=None, device="cpu"):
    """An encoder as is, the encoder of an autoencoder run folder or weights file, or (None) the shipped φ."""
    if phi is None:
        from sasmi.weights import shipped

        phi = shipped("phi")
    if isinstance(phi, (str, os.PathLike)):
        from sasmi.gan.autoencoder import load_encoder

        if not Path(phi).exists():
            raise SasmiError(f"--phi {phi}: no such folder or file (expected an autoencoder run)")
        return load_encoder(phi, device=device)
    return phi


def describe_phi(encoder) -> str:
    """Which φ measured a figure, for reports: the shipped one by name, another by its checkpoint file,
    each with its weights' fingerprint (sasmi.eval.cache), so two figures can be told comparable."""
    from sasmi.eval.cache import encoder_fingerprint
    from sasmi.weights import HERE

    path = Path(encoder.checkpoint)
    name = f"the shipped φ ({path.name})" if path.resolve().parent == HERE else str(path)
    return f"{name}, weights {encoder_fingerprint(encoder)[:12]}"


READ_BLOCK = 512  # images read (float32) at a time


def load_images(paths: Sequence[str | os.PathLike], size: int) -> np.ndarray:
    """(N, size, size) float32 in [0, 1]; a file that cannot be read is a SasmiError naming it."""
    from sasmi.preprocess import load_image  # imports torch: only when images are read

    out = np.empty((len(paths), size, size), dtype=np.float32)
    for i, path in enumerate(paths):
        out[i] = load_image(path, size)
    return out


def phi_features(encoder, images: np.ndarray | Sequence[str | os.PathLike], batch: int = 32) -> np.ndarray:
    """φ of image files or of an (N, H, W) array in [0, 1] → (N, D) float64.

    Images are brought to `encoder.image_size` as in training. The encoder is put in eval
    mode so that φ of an image does not depend on the batch it is in.
    """
    import torch

    from sasmi.preprocess import fit_image, to_batch

    size = encoder.image_size
    if isinstance(images, np.ndarray):
        images = np.stack([fit_image(im, size) for im in images]) if images.shape[1:] != (size, size) else images
    else:
        images = load_images(images, size)
    if len(images) == 0:
        raise SasmiError("phi_features: no images")
    encoder.eval()
    device = next(encoder.parameters()).device
    feats = []
    with torch.no_grad():
        for start in tqdm(range(0, len(images), batch), desc="φ", unit="batch", leave=False, disable=None):
            x = to_batch(images[start:start + batch], device)  # (B, 1, S, S) in [-1, 1]
            phi = encoder(x)  # (B, D)
            assert phi.ndim == 2 and phi.shape[0] == x.shape[0], phi.shape
            feats.append(phi.double().cpu().numpy())
    return np.concatenate(feats)  # (N, D)


def image_paths(folder: str | os.PathLike) -> list[Path]:
    paths = list_images(folder)
    if not paths:
        raise SasmiError(f"{folder}: no images (png, jpg, tif, tiff, npy) in it")
    return paths


def load_set(name: str, folder: str | os.PathLike, encoder, batch: int = 32, cache_dir: str | os.PathLike | None = None,
             log: Callable[[str], None] = lambda message: None) -> FeatureSet:
    """Images and φ of a folder; φ is read from (or written to) `cache_dir` when one is given."""
    paths = image_paths(folder)
    cached = cache.cache_file(cache_dir, folder, paths, encoder) if cache_dir is not None else None
    phi = cache.read(cached, len(paths)) if cached is not None and cached.is_file() else None
    log(f"φ of {name}: {len(paths)} images from {folder}" + (f" (φ from the cache {cached})" if phi is not None else ""))
    size = encoder.image_size
    pixels = np.empty((len(paths), size, size), np.uint8)
    blocks = []
    for start in tqdm(range(0, len(paths), READ_BLOCK), desc=f"φ of {name}", unit="block", leave=False, disable=None):
        images = load_images(paths[start:start + READ_BLOCK], size)  # (b, S, S) float32 in [0, 1]
        pixels[start:start + len(images)] = to_pixels(images)
        if phi is None:
            blocks.append(phi_features(encoder, images, batch))
    if phi is None:
        phi = np.concatenate(blocks)
        if cached is not None:
            cache.write(cached, phi)
    return FeatureSet(name, Path(folder), pixels, phi, tuple(p.name for p in paths))
