"""Grayscale image IO shared by the renderer, the GAN and the evaluation.

Every reader returns float32 arrays of shape (H, W) in [0, 1]; every writer is atomic
(temp file + rename) so a killed job never leaves a truncated image behind.
"""
from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path
from typing import Iterator

import numpy as np
from PIL import Image

from sasmi.errors import SasmiError

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".npy")
_UMASK = os.umask(0o022)
os.umask(_UMASK)
FORMATS = {"png": ".png", "tiff16": ".tiff", "npy": ".npy"}


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside `path`; rename it onto `path` only if the block succeeds."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp" + path.suffix, dir=path.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, 0o666 & ~_UMASK)  # mkstemp creates 0600; give the file the usual permissions
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def write_text(path: str | os.PathLike, text: str) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def to_uint8(image01: np.ndarray) -> np.ndarray:
    return np.round(np.clip(image01, 0.0, 1.0) * 255.0).astype(np.uint8)


def write_gray(path: str | os.PathLike, image01: np.ndarray) -> None:
    """Write an (H, W) image in [0, 1]; the suffix picks 8-bit PNG, 16-bit TIFF or float32 NPY."""
    path = Path(path)
    if image01.ndim != 2:
        raise ValueError(f"expected an (H, W) image, got shape {image01.shape}")
    with atomic_path(path) as tmp:
        if path.suffix == ".png":
            Image.fromarray(to_uint8(image01), mode="L").save(tmp, format="PNG")
        elif path.suffix in (".tif", ".tiff"):
            import tifffile

            tifffile.imwrite(tmp, np.round(np.clip(image01, 0, 1) * 65535).astype(np.uint16))
        elif path.suffix == ".npy":
            with open(tmp, "wb") as f:
                np.save(f, image01.astype(np.float32))
        else:
            raise ValueError(f"unsupported image suffix {path.suffix!r}")


def write_mask(path: str | os.PathLike, mask: np.ndarray) -> None:
    """Write an (H, W) uint8 label mask as PNG (values kept as they are, not scaled)."""
    with atomic_path(path) as tmp:
        Image.fromarray(mask.astype(np.uint8), mode="L").save(tmp, format="PNG")


def _scale_integer(a: np.ndarray, path: Path) -> np.ndarray:
    if a.dtype == np.uint8:
        return a.astype(np.float32) / 255.0
    if a.dtype == np.uint16:
        return a.astype(np.float32) / 65535.0
    if a.dtype in (np.int32, np.uint32) and a.max(initial=0) > 255:  # PIL's mode "I" for 16-bit PNG
        return a.astype(np.float32) / 65535.0
    if np.issubdtype(a.dtype, np.integer):
        return a.astype(np.float32) / 255.0
    if np.issubdtype(a.dtype, np.floating):
        return np.clip(a.astype(np.float32), 0.0, 1.0)
    raise SasmiError(f"{path}: unsupported pixel type {a.dtype}")


def read_gray(path: str | os.PathLike) -> np.ndarray:
    """Read PNG/JPEG/TIFF (8 or 16 bit) or NPY as an (H, W) float32 array in [0, 1].

    Colour images are converted to luminance. Raises SasmiError naming the file if it
    cannot be read.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    try:
        if suffix == ".npy":
            a = np.load(path, allow_pickle=False)
        elif suffix in (".tif", ".tiff"):
            import tifffile

            a = tifffile.imread(path)
        else:
            with Image.open(path) as im:
                if im.mode in ("RGB", "RGBA", "P", "LA", "CMYK", "YCbCr"):
                    im = im.convert("L")
                a = np.asarray(im)
    except (OSError, ValueError, SyntaxError) as e:
        raise SasmiError(f"{path}: cannot read image ({e})") from None
    if a.ndim == 3:
        if a.shape[-1] in (3, 4):
            a = a[..., :3].mean(axis=-1).astype(a.dtype)
        elif a.shape[0] == 1:
            a = a[0]
    if a.ndim != 2 or min(a.shape) == 0:
        raise SasmiError(f"{path}: expected a 2-D grayscale image, got shape {a.shape}")
    return _scale_integer(a, path)


def list_images(folder: str | os.PathLike) -> list[Path]:
    """Sorted image files directly in `folder` or in its `images/` subfolder (a render set)."""
    folder = Path(folder)
    if not folder.is_dir():
        raise SasmiError(f"{folder}: not a folder")
    if (folder / "images").is_dir():
        folder = folder / "images"
    return sorted(p for p in folder.rglob("*") if p.suffix.lower() in IMAGE_SUFFIXES and p.is_file()
                  and not p.name.startswith("."))
