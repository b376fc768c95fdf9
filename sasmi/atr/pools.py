"""The chips an ATR bench draws from: real targets and negatives, synthetic targets and negatives.

Negatives of another sonar than the targets let a classifier score by telling sonars apart
instead of targets from seabed, so by default a real negative is kept only when the MANIFEST.csv
beside its folder (`sasmi split` writes one per side) names it as of a sonar the real targets come
from. A chip's sonar is the MANIFEST's `sonar` column where it has one, else the first word of its
`scene_group` (the shared chips' groups read milco_g012, sassed_t03, klsg_block04).
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sasmi.chips.build import MANIFEST, read_manifest
from sasmi.errors import SasmiError
from sasmi.images import list_images
from sasmi.preprocess import load_image


@dataclass(frozen=True)
class Pool:
    """(N, S, S) images in [0, 1] and their files, in the same order."""
    images: np.ndarray
    names: tuple[str, ...]

    def __len__(self) -> int:
        return len(self.images)

    def keep(self, chosen: np.ndarray) -> "Pool":
        return Pool(self.images[chosen], tuple(self.names[i] for i in np.flatnonzero(chosen)))


def load_pool(folder: Path, size: int, what: str) -> Pool:
    """Every readable image under `folder`; unreadable files are skipped with one warning each."""
    if not folder.is_dir():
        raise SasmiError(f"{what} {folder}: not a folder")
    images, names = [], []
    for path in list_images(folder):
        try:
            images.append(load_image(path, size))
            names.append(str(path.resolve()))
        except SasmiError as e:
            warnings.warn(f"skipping {e}", stacklevel=2)
    if not images:
        raise SasmiError(f"{what} {folder}: no readable image in it")
    return Pool(np.stack(images), tuple(names))


def split_folders(folder: Path) -> tuple[Path, Path | None]:
    """A folder with targets/ (and seafloor/), or a folder of target chips (a render set, a translation)."""
    targets = folder / "targets" if (folder / "targets").is_dir() else folder
    seafloor = folder / "seafloor" if (folder / "seafloor").is_dir() else None
    return targets, seafloor


def sonars(folder: Path) -> dict[str, str] | None:
    """Chip file (resolved) → sonar, from the MANIFEST.csv in `folder` or its parent; None where there is none."""
    for place in (folder, folder.parent):
        path = place / MANIFEST
        if path.is_file():
            rows = read_manifest(path, columns=("file",), what="")
            return {str((place / r.get("file", "")).resolve()): r.get("sonar") or r.get("scene_group", "").split("_")[0]
                    for r in rows}
    return None


def same_sonar(negatives: Pool, folder: Path, wanted: set[str], what: str) -> Pool:
    """The negatives of a sonar in `wanted`; all of them where no MANIFEST says which is which."""
    known = sonars(folder)
    if known is None or not wanted:
        return negatives
    chosen = np.array([known.get(name) in wanted for name in negatives.names])
    if not chosen.any():
        raise SasmiError(f"{what} {folder}: no chip of the targets' sonar ({', '.join(sorted(wanted))}); "
                         "pass --any-sonar to use them all")
    return negatives.keep(chosen)


def target_sonars(*folders: Path) -> set[str]:
    """The sonars of the real target chips, as their MANIFESTs name them (empty where none does)."""
    found: set[str] = set()
    for folder in folders:
        known = sonars(folder)
        if known:
            found |= {known[f] for f in map(lambda p: str(p.resolve()), list_images(folder)) if known.get(f)}
    return found
