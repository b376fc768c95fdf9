"""φ of a folder cached on disk, so that evaluating again against the same real set skips
the encoder (the slow part: minutes on a CPU for thousands of chips).

The key covers everything φ depends on: every image's path relative to the folder, its size
and its modification time (a file added, removed or rewritten changes it), and the
encoder's weights and input size (another φ run, or the same run retrained, changes it).
A cache file is written atomically; a missing or unreadable one is recomputed.
"""
from __future__ import annotations

import hashlib
import os
from pathlib import Path
from typing import Sequence

import numpy as np

from sasmi.images import atomic_path

VERSION = 1  # bump when φ's preprocessing changes, so that old entries are not read


def default_cache_dir() -> Path:
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "sasmi" / "phi"


def folder_fingerprint(folder: str | os.PathLike, paths: Sequence[Path]) -> str:
    h = hashlib.sha256()
    for path in paths:
        st = path.stat()
        h.update(f"{path.relative_to(folder)}\t{st.st_size}\t{st.st_mtime_ns}\n".encode())
    return h.hexdigest()


def encoder_fingerprint(encoder) -> str:
    """Identity of the loaded φ checkpoint: a hash of its weights (and input size), so it does
    not depend on where or how the run folder stores them."""
    import torch

    h = hashlib.sha256(f"v{VERSION} size {encoder.image_size}\n".encode())
    for name, tensor in sorted(encoder.state_dict().items()):
        t = tensor.detach().cpu().contiguous()
        h.update(f"{name} {t.dtype} {tuple(t.shape)}\n".encode())
        h.update(t.reshape(-1).view(torch.uint8).numpy().tobytes())  # raw bytes: any dtype
    return h.hexdigest()


def cache_file(cache_dir: str | os.PathLike, folder: str | os.PathLike, paths: Sequence[Path], encoder) -> Path:
    folder = Path(folder)
    key = hashlib.sha256(f"{folder_fingerprint(folder, paths)} {encoder_fingerprint(encoder)}".encode())
    return Path(cache_dir) / f"{folder.resolve().name}-{key.hexdigest()[:32]}.npy"


def read(path: Path, n: int) -> np.ndarray | None:
    """(n, D) float64 from a cache file, or None when it is missing, unreadable or of another size."""
    try:
        phi = np.load(path, allow_pickle=False)
    except (OSError, ValueError):
        return None
    return phi.astype(np.float64) if phi.ndim == 2 and len(phi) == n else None


def write(path: Path, phi: np.ndarray) -> None:
    """Stored as float32 when that is exact (the encoder computes in float32), else float64."""
    small = phi.astype(np.float32)
    with atomic_path(path) as tmp:
        np.save(tmp, small if np.array_equal(small, phi) else phi)
