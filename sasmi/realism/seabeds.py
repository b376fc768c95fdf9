"""Real-like seabeds without real chips: a real floor's seabed spectrum under fresh random phases.

A floor chip blurred over SEABED px is its seabed (sasmi.realism.floors): its patches, bands,
ripples and range profile. Seen at COARSE px, the log of a seabed is its mean, its range profile
(the mean of each range column) and a field whose Fourier amplitudes say how rough it is at each
scale and in each direction. Drawing that field's phases afresh makes a new seabed of the same
character that is no real chip (phase randomisation, Theiler et al. 1992). A seabeds file keeps,
for each seafloor chip, the mean, the profile and the amplitudes: statistics, no image. The
shipped one (sasmi/weights/seabeds.pt, docs/models.md) holds those of the seafloor chips of the
shared target chips' sonar, so that `sasmi generate` lays renders on real-like floors anywhere.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import ndimage

from sasmi.errors import SasmiError
from sasmi.images import list_images

COARSE = 32      # px: a seabed (blurred over SEABED px at 128) keeps nothing finer than this grid shows
SEABED = 4.0     # px at 128: as sasmi.realism.floors.SEABED
KIND = "seabeds"


@dataclass(frozen=True)
class Seabeds:
    mean: np.ndarray        # (N,) each chip's mean log seabed
    profile: np.ndarray     # (N, COARSE) its log seabed's range profile, less the mean
    amplitude: np.ndarray   # (N, COARSE, COARSE // 2 + 1) |rfft2| of the rest
    path: Path | None = None


def log_seabed(chip01: np.ndarray) -> np.ndarray:
    """(COARSE, COARSE): the log seabed of a floor chip (any size, in [0, 1]) on the coarse grid."""
    import torch
    import torch.nn.functional as F

    scale = chip01.shape[0] / 128  # SEABED is in px of a 128 px chip
    seabed = ndimage.gaussian_filter(chip01.astype(np.float64), SEABED * scale) + 1e-3
    coarse = F.interpolate(torch.from_numpy(seabed)[None, None], size=(COARSE, COARSE), mode="area")
    return np.log(coarse[0, 0].numpy())


def fit_seabeds(floors: str | os.PathLike) -> Seabeds:
    """The Seabeds of every floor chip in a folder."""
    from sasmi.preprocess import load_image

    paths = list_images(floors)
    if not paths:
        raise SasmiError(f"{floors}: no image (png, jpg, tif, tiff, npy) in it")
    logs = np.stack([log_seabed(load_image(p, 128)) for p in paths])              # (N, C, C)
    mean = logs.mean(axis=(1, 2))
    profile = logs.mean(axis=1) - mean[:, None]                                    # (N, C): per range column
    rest = logs - mean[:, None, None] - profile[:, None, :]
    return Seabeds(mean, profile, np.abs(np.fft.rfft2(rest)))


def draw_seabed(seabeds: Seabeds, shape: tuple[int, int], rng: np.random.Generator) -> np.ndarray:
    """(H, W) > 0: a new seabed, one chip's mean, profile and amplitudes under random phases, at `shape`."""
    import torch
    import torch.nn.functional as F

    k = int(rng.integers(len(seabeds.mean)))
    # the phases of white noise's transform: random, and exactly those of a real field
    phase = np.angle(np.fft.rfft2(rng.standard_normal((COARSE, COARSE))))
    rest = np.fft.irfft2(seabeds.amplitude[k] * np.exp(1j * phase), s=(COARSE, COARSE))
    log = seabeds.mean[k] + seabeds.profile[k][None, :] + rest
    fine = F.interpolate(torch.from_numpy(np.exp(log))[None, None], size=shape, mode="bilinear", align_corners=False)
    return ndimage.gaussian_filter(fine[0, 0].numpy(), SEABED * shape[0] / 128)


def save_seabeds(seabeds: Seabeds, out: str | os.PathLike, about: dict | None = None) -> Path:
    """Write a seabeds file (tensors and plain types: loads with torch.load(weights_only=True))."""
    import torch

    from sasmi import __version__
    from sasmi.gan.run import FORMAT
    from sasmi.images import write_torch

    data = {"format": FORMAT, "sasmi": __version__, "kind": KIND, "about": about or {},
            "state": {name: torch.from_numpy(np.ascontiguousarray(getattr(seabeds, name), dtype=np.float32))
                      for name in ("mean", "profile", "amplitude")}}
    return write_torch(out, data)


def load_seabeds(path: str | os.PathLike) -> Seabeds:
    """A seabeds file, or one SasmiError naming it."""
    import torch

    from sasmi.gan.run import FORMAT

    path = Path(path)
    if not path.is_file():
        raise SasmiError(f"{path}: no such seabeds file")
    try:
        data = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as e:  # truncated, random bytes, a pickle carrying code
        raise SasmiError(f"{path}: not a readable seabeds file ({type(e).__name__})") from None
    if not isinstance(data, dict) or data.get("kind") != KIND:
        raise SasmiError(f"{path}: not a seabeds file (kind {data.get('kind') if isinstance(data, dict) else None!r})")
    if data.get("format") != FORMAT:
        raise SasmiError(f"{path}: seabeds format {data.get('format')!r}; this sasmi reads format {FORMAT} "
                         f"(written by {data.get('sasmi', 'another version')})")
    try:
        state = {k: data["state"][k].double().numpy() for k in ("mean", "profile", "amplitude")}
        seabeds = Seabeds(**state, path=path)
        ok = (seabeds.mean.ndim == 1 and len(seabeds.mean) > 0
              and seabeds.profile.shape == (len(seabeds.mean), COARSE)
              and seabeds.amplitude.shape == (len(seabeds.mean), COARSE, COARSE // 2 + 1))
    except (KeyError, TypeError, AttributeError):
        ok = False
    if not ok:
        raise SasmiError(f"{path}: its seabeds tables are missing or of the wrong shape")
    return seabeds
