"""`sasmi render --format wds`: WebDataset tar shards instead of five small files per chip.

Layout of OUT:
    run.json                   as for a render set, plus per_shard
    shards/shard-000000.tar    samples 0..per_shard-1, in index order; per sample NNNNNN:
        NNNNNN.png             8-bit gray image
        NNNNNN.mask.png        0 seafloor, 1 target, 2 acoustic shadow (sasmi.masks)
        NNNNNN.instances.png   k + 1 where target k is visible
        NNNNNN.shadows.png     k + 1 where target k casts its shadow
        NNNNNN.json            the chip's labels (sasmi.labels; image and mask name the sample's files)

`webdataset.WebDataset("OUT/shards/shard-{000000..000009}.tar")` reads them (run.json holds
that pattern). A shard is rendered whole into a hidden temp folder, packed into a temp tar
and renamed, so resuming works per shard: complete shards are kept, the rest rendered again.
Shards are claimed like chips (sasmi.renderset.claims), so processes and --shard I/N share one folder.
"""
from __future__ import annotations

import io
import json
import shutil
import tarfile
import tempfile
from pathlib import Path

import numpy as np
from tqdm import tqdm

from sasmi.renderset.claims import Claims
from sasmi.renderset.write import RenderJob, prepare, render_chip, run_tasks, write_one
from sasmi.errors import SasmiError
from sasmi.images import atomic_path, write_text

# the files write_one makes for a chip, and their suffix in a sample
_PARTS = (("images", ".png", "png"), ("masks", ".png", "mask.png"), ("instances", ".png", "instances.png"),
          ("shadows", ".png", "shadows.png"), ("labels", ".json", "json"))


def shard_path(out: Path, k: int) -> Path:
    return out / "shards" / f"shard-{k:06d}.tar"


def shard_count(count: int, per_shard: int) -> int:
    return -(-count // per_shard)


def _samples(job: RenderJob, k: int) -> range:
    return range(k * job.per_shard, min((k + 1) * job.per_shard, job.count))


def shard_complete(job: RenderJob, k: int) -> bool:
    """The tar exists and holds every sample it should (a grown --count refills the last shard)."""
    path = shard_path(job.out, k)
    if not path.is_file():
        return False
    try:
        with tarfile.open(path) as tar:
            labels = sum(1 for m in tar if m.name.endswith(".json"))
    except (OSError, tarfile.TarError):
        return False
    return labels == len(_samples(job, k))


def complete_samples(job: RenderJob) -> int:
    """Samples in the complete tar shards of the job's --shard."""
    return sum(len(_samples(job, k)) for k in range(job.shard[0], shard_count(job.count, job.per_shard), job.shard[1])
               if shard_complete(job, k))


def missing_shards(job: RenderJob) -> list[int]:
    return [k for k in range(shard_count(job.count, job.per_shard)) if not shard_complete(job, k)]


def _add(tar: tarfile.TarFile, name: str, data: bytes) -> None:
    info = tarfile.TarInfo(name)
    info.size, info.mode, info.mtime = len(data), 0o644, 0  # same bytes from every writer
    tar.addfile(info, io.BytesIO(data))


def write_shard(job: RenderJob, k: int, threads: int | None = None) -> int:
    """Render shard k's samples and write its tar; returns the number of samples."""
    path = shard_path(job.out, k)
    with tempfile.TemporaryDirectory(prefix=f".{path.stem}.", dir=path.parent) as tmp, atomic_path(path) as tar_tmp:
        chips = Path(tmp)
        with tarfile.open(tar_tmp, "w", format=tarfile.PAX_FORMAT) as tar:
            for index in _samples(job, k):
                rendered = render_chip(job, index, write=False, threads=threads)
                write_one(chips, index, rendered.image, rendered, "png")
                name = f"{index:06d}"
                label = json.loads((chips / "labels" / f"{name}.json").read_text())
                label.update(image=f"{name}.png", mask=f"{name}.mask.png")
                for folder, suffix, part in _PARTS:
                    data = json.dumps(label).encode() if part == "json" else (chips / folder / (name + suffix)).read_bytes()
                    _add(tar, f"{name}.{part}", data)
                    (chips / folder / (name + suffix)).unlink()
    return len(_samples(job, k))


def render_shards(job: RenderJob, progress: bool = True) -> Path:
    """Render this job's tar shards into job.out/shards (resuming, beside other processes); returns job.out."""
    job, _ = prepare(job)
    (job.out / "shards").mkdir(exist_ok=True)
    claims = Claims(job.out / "claims")
    mine = range(job.shard[0], shard_count(job.count, job.per_shard), job.shard[1])
    todo = [k for k in mine if not shard_complete(job, k)]

    def claim(k: int) -> bool:
        if not claims.take(f"shard-{k:06d}"):
            return False
        if shard_complete(job, k):
            claims.release(f"shard-{k:06d}")
            return False
        for stale in (job.out / "shards").glob(f".shard-{k:06d}.*"):  # temps of a dead writer of this shard
            shutil.rmtree(stale) if stale.is_dir() else stale.unlink(missing_ok=True)
        return True

    total = sum(len(_samples(job, k)) for k in mine)
    with tqdm(total=total, initial=total - sum(len(_samples(job, k)) for k in todo), unit="img",
              desc="render shards", disable=not progress, dynamic_ncols=True) as bar, claims.kept_alive():
        stream = run_tasks(job, write_shard, todo, claim)
        try:
            for k, samples in stream:
                claims.release(f"shard-{k:06d}")
                bar.update(samples)
        finally:
            stream.close()
            claims.release_all()
    if not missing_shards(job):
        n = shard_count(job.count, job.per_shard)
        run_json = job.out / "run.json"
        record = json.loads(run_json.read_text())
        record["shards"] = f"shards/shard-{{000000..{n - 1:06d}}}.tar"
        write_text(run_json, json.dumps(record, indent=2))
        claims.remove_folder()
    return job.out


def has_shards(folder: str | Path) -> bool:
    folder = Path(folder)
    return any((folder / "shards").glob("shard-*.tar")) or any(folder.glob("shard-*.tar"))


def shard_files(folder: str | Path) -> list[Path]:
    """The tar shards of a --format wds render (OUT or OUT/shards), in order."""
    folder = Path(folder)
    found = sorted((folder / "shards").glob("shard-*.tar")) or sorted(folder.glob("shard-*.tar"))
    if not found:
        raise SasmiError(f"{folder}: no WebDataset shards (shards/shard-NNNNNN.tar) in it")
    return found


def _decode(data: bytes):
    from PIL import Image

    with Image.open(io.BytesIO(data)) as im:
        return np.asarray(im)  # palette masks stay ids; images are mode L


def read_shards(folder: str | Path, size: int, masks: bool = False) -> tuple[list, list | None]:
    """Every sample of a wds render, in sample order, as sasmi.gan.data.ImageSet holds a render set:
    images (1, h, w) float32 in [0, 1] with short side `size`, and with masks=True the class
    masks (1, h, w) uint8 resized (nearest) to the same h, w; else None."""
    import torch
    import torch.nn.functional as F
    import webdataset as wds

    from sasmi.preprocess import check_size, resize_short_side

    check_size(size)
    images, classes = [], [] if masks else None
    try:
        for sample in wds.WebDataset([str(p) for p in shard_files(folder)], shardshuffle=False, empty_check=False):
            if "png" not in sample or (masks and "mask.png" not in sample):
                raise SasmiError(f"{sample['__url__']}: sample {sample['__key__']} has no image or mask")
            image = resize_short_side(_decode(sample["png"]).astype(np.float32) / 255.0, size)
            images.append(image)
            if classes is not None:
                mask = torch.from_numpy(_decode(sample["mask.png"]).astype(np.uint8))[None, None]
                classes.append(F.interpolate(mask.float(), size=tuple(image.shape[1:]), mode="nearest")[0]
                               .to(torch.uint8))
    except (OSError, ValueError, tarfile.TarError) as e:
        raise SasmiError(f"{folder}: unreadable shard ({type(e).__name__}: {e})") from None
    if not images:
        raise SasmiError(f"{folder}: its shards hold no sample")
    return images, classes


def read_shard_images(folder: str | Path, size: int) -> list:
    """The images of read_shards: a list of (1, h, w) float32 tensors in [0, 1]."""
    return read_shards(folder, size)[0]
