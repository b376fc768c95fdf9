"""Grayscale image IO shared by the renderer, the GAN and the evaluation.

Every reader returns float32 arrays of shape (H, W) in [0, 1]; every writer is atomic
(temp file + rename) so a killed job never leaves a truncated image behind. A file that
cannot be a chip (truncated, a decompression bomb, NaN pixels, /dev/zero) is a SasmiError
naming it; `read_folder` skips such files with one warning line each.
"""
from __future__ import annotations

import contextlib
import errno
import fcntl
import math
import os
import shutil
import stat
import sys
import tempfile
import warnings
from pathlib import Path
from typing import Callable, Iterator, Sequence, TypeVar

import numpy as np
from PIL import Image

from sasmi.errors import SasmiError, first_line, one_line
from sasmi.limits import IMAGE_MAX_BYTES, IMAGE_MAX_PIXELS

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".npy")
_UMASK = os.umask(0o022)
os.umask(_UMASK)
FORMATS = {"png": ".png", "tiff16": ".tiff", "npy": ".npy"}
T = TypeVar("T")
TEMPORARIES = ".*.tmp*"  # the glob of atomic_path's temporaries: what a killed writer leaves


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
    except BaseException as e:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        if isinstance(e, OSError) and e.filename in (None, tmp):  # a failed write: name the file the user asked for
            raise SasmiError(f"{path}: cannot write ({e.strerror or e}); nothing was written") from e
        raise


def write_text(path: str | os.PathLike, text: str) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def check_room(folder: str | os.PathLike, need: int, what: str) -> None:
    """A SasmiError, before any work, when the disk of `folder` (or of its nearest existing parent) clearly
    has less free space than the `need` bytes that `what` will write."""
    place = Path(folder).absolute()
    while not place.exists() and place != place.parent:
        place = place.parent
    free = shutil.disk_usage(place).free
    if need > free:
        raise SasmiError(f"{folder}: {what} need about {_amount(need)} and its disk has {_amount(free)} "
                         f"free; free some space or choose another --out")


def _amount(size: int) -> str:
    return f"{size / 1e6:,.0f} MB" if size >= 1e6 else f"{size / 1e3:,.0f} kB"


def write_torch(path: str | os.PathLike, data: dict) -> Path:
    """torch.save `data` to `path` atomically. Serialised in memory first: a full disk is then an
    OSError of this write (torch's own file writer reports it as a RuntimeError), and the same data
    give the same bytes (a torch archive written to a file is named after that file, here a random
    temporary name)."""
    import io

    import torch

    buffer = io.BytesIO()
    torch.save(data, buffer)
    try:
        with atomic_path(path) as tmp:
            tmp.write_bytes(buffer.getvalue())
    except SasmiError as e:
        if isinstance(e.__cause__, OSError) and e.__cause__.errno == errno.ENOSPC:
            free = shutil.disk_usage(Path(path).parent).free
            raise SasmiError(f"{path}: no space left on the disk for its {buffer.tell() / 1e6:.1f} MB "
                             f"({free / 1e6:.1f} MB free); nothing was written") from None
        raise
    return Path(path)


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


def _scale(a: np.ndarray, path: Path) -> np.ndarray:
    """Pixels of any integer or float type -> float32 in [0, 1]."""
    if a.dtype.byteorder not in ("=", "|"):
        a = a.astype(a.dtype.newbyteorder("="))
    if a.dtype == np.bool_:
        return a.astype(np.float32)
    if a.dtype == np.uint8:
        return a.astype(np.float32) / 255.0
    if a.dtype == np.uint16:
        return a.astype(np.float32) / 65535.0
    if np.issubdtype(a.dtype, np.integer):  # PIL's mode "I" holds 16-bit PNGs as int32
        scale = 65535.0 if a.max(initial=0) > 255 else 255.0
        return np.clip(a.astype(np.float32) / scale, 0.0, 1.0)
    if np.issubdtype(a.dtype, np.floating):
        if not np.isfinite(a).all():
            raise SasmiError(f"{path}: holds NaN or infinite pixel values (allowed: finite values, read as [0, 1])")
        return np.clip(a.astype(np.float32), 0.0, 1.0)
    raise SasmiError(f"{path}: unsupported pixel type {a.dtype} (allowed: integers or floats)")


def _check_file(path: Path) -> None:
    """A regular file of bounded size, checked before a decoder opens it (/dev/zero, a FIFO, a folder)."""
    try:
        st = path.stat()
    except OSError as e:
        raise SasmiError(f"{path}: cannot read image ({e.strerror or e})") from None
    if not stat.S_ISREG(st.st_mode):
        raise SasmiError(f"{path}: not a regular file")
    if st.st_size > IMAGE_MAX_BYTES:
        raise SasmiError(f"{path}: {st.st_size} bytes is too large for an image (allowed: <= {IMAGE_MAX_BYTES})")


def _check_pixels(path: Path, shape: tuple[int, ...]) -> None:
    """Refuse an image whose decoded pixels would not fit, before decoding it (decompression bombs)."""
    pixels = math.prod(shape)
    if pixels > IMAGE_MAX_PIXELS:
        raise SasmiError(f"{path}: {' x '.join(map(str, shape))} = {pixels} values is too large "
                         f"(allowed: <= {IMAGE_MAX_PIXELS}, 8192² pixels; a decompression bomb or not a chip)")


GRAY_MODES = ("L", "I", "F", "I;16", "I;16B", "I;16L", "I;16N")  # everything else is converted to "L"


def _read_pil(path: Path) -> np.ndarray:
    with warnings.catch_warnings():
        warnings.simplefilter("error", Image.DecompressionBombWarning)  # PIL warns at 89M pixels: refuse
        with Image.open(path) as im:
            _check_pixels(path, im.size)
            if im.mode not in GRAY_MODES:
                im = im.convert("L")
            return np.asarray(im)


def _read_npy(path: Path) -> np.ndarray:
    a = np.load(path, mmap_mode="r", allow_pickle=False)  # mapped: the header's shape is checked, not trusted
    _check_pixels(path, a.shape)
    return np.array(a)


def _read_tiff(path: Path) -> np.ndarray:
    import tifffile

    with tifffile.TiffFile(path) as tif:
        page = tif.pages[0]
        _check_pixels(path, page.shape)
        return page.asarray()


def read_gray(path: str | os.PathLike) -> np.ndarray:
    """Read PNG/JPEG/TIFF (8 or 16 bit) or NPY as an (H, W) float32 array in [0, 1].

    Colour images are converted to luminance. Raises SasmiError naming the file if it
    cannot be read: missing, not a regular file, too large, truncated, a decompression
    bomb, an odd pixel type, NaN or infinite values.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    _check_file(path)
    try:
        if suffix == ".npy":
            a = _read_npy(path)
        elif suffix in (".tif", ".tiff"):
            a = _read_tiff(path)
        else:
            a = _read_pil(path)
    except SasmiError:
        raise
    except (Image.DecompressionBombError, Image.DecompressionBombWarning) as e:
        raise SasmiError(f"{path}: too many pixels, a decompression bomb? ({first_line(e, 160)})") from None
    except Exception as e:  # decoders raise many types for broken files (OSError, ValueError, struct.error, ...)
        raise SasmiError(f"{path}: cannot read image ({type(e).__name__}: {first_line(e, 160)})") from None
    if a.ndim == 3:
        if a.shape[-1] in (3, 4):
            a = a[..., :3].mean(axis=-1).astype(a.dtype)
        elif a.shape[-1] in (1, 2):  # gray, gray + alpha
            a = a[..., 0]
        elif a.shape[0] == 1:
            a = a[0]
    if a.ndim != 2 or min(a.shape) == 0:
        raise SasmiError(f"{path}: expected a 2-D grayscale image, got shape {a.shape}")
    return _scale(a, path)


def print_warning(message: str) -> None:
    print(f"sasmi: warning: {message}", file=sys.stderr)


def read_usable(paths: Sequence[Path], load: Callable[[Path], T] = read_gray, where: str | os.PathLike = "",
                warn: Callable[[str], None] = print_warning) -> tuple[list[Path], list[T]]:
    """(paths, loaded) of every path that `load` can read; each other one is skipped with one warning
    line, then one line with the count. SasmiError only if nothing usable is left."""
    kept, loaded, skipped = [], [], 0
    for path in paths:
        try:
            loaded.append(load(path))
            kept.append(path)
        except SasmiError as e:
            warn(f"skipped {one_line(e, 300)}")
            skipped += 1
    place = f" in {where}" if where else ""
    if not kept:
        raise SasmiError(f"{where or 'input'}: no usable image ({skipped} of {len(paths)} files skipped)")
    if skipped:
        warn(f"skipped {skipped} of {len(paths)} images{place}; using the other {len(kept)}")
    return kept, loaded


def read_folder(folder: str | os.PathLike, load: Callable[[Path], T] = read_gray) -> tuple[list[Path], list[T]]:
    """read_usable over list_images(folder): the one way to read a folder of chips."""
    paths = list_images(folder)
    if not paths:
        raise SasmiError(f"{folder}: no image files ({', '.join(IMAGE_SUFFIXES)}) in it")
    return read_usable(paths, load, folder)


def list_images(folder: str | os.PathLike) -> list[Path]:
    """Sorted image files directly in `folder` or in its `images/` subfolder (a render set)."""
    folder = Path(folder)
    if not folder.is_dir():
        raise SasmiError(f"{folder}: not a folder")
    if (folder / "images").is_dir():
        folder = folder / "images"
    return sorted(p for p in folder.rglob("*") if p.suffix.lower() in IMAGE_SUFFIXES and p.is_file()
                  and not p.name.startswith("."))


class FolderLock:
    """An exclusive lock on a run folder (RUN/.lock), or a SasmiError when another process holds it. The
    kernel drops it when its process ends, however it ends: a killed command never leaves it held. A
    command that ends removes the file as well, so that finished folders hold only what they made."""

    def __init__(self, folder: str | os.PathLike, what: str):
        self.path = Path(folder) / ".lock"
        self.made = not self.path.parent.exists()  # removed again on release if the command wrote nothing in it
        while True:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            try:
                self.file = open(self.path, "a+")
            except FileNotFoundError:  # another command's release removed its empty folder in between
                continue
            try:
                fcntl.flock(self.file, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                self.file.seek(0)
                holder = self.file.read().strip() or "another process"
                self.file.close()
                raise SasmiError(f"{folder}: {holder} is {what} in this folder; wait for it to end, "
                                 f"or choose another --out") from None
            # a holder that released between our open and our lock has removed the file we locked: lock the new one
            try:
                if os.stat(self.path).st_ino == os.fstat(self.file.fileno()).st_ino:
                    break
            except FileNotFoundError:
                pass
            self.file.close()
        self.file.seek(0)
        self.file.truncate()
        self.file.write(f"sasmi (pid {os.getpid()})")
        self.file.flush()

    def release(self) -> None:
        self.path.unlink(missing_ok=True)  # while still held: no other process can hold this file now
        self.file.close()  # closing drops the lock
        if self.made:
            try:
                self.path.parent.rmdir()  # a command refused before its first file leaves no folder behind
            except OSError:
                pass  # not empty: the command's output
