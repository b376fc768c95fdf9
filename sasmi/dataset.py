"""Writes a render set: images/, masks/, labels.jsonl, run.json — atomically and resumably.

Layout of OUT:
    run.json            resolved preset, seed, size, spp, format, versions (written first)
    images/000000.png   8-bit gray (or .tiff 16-bit, .npy float32)
    masks/000000.png    0 seafloor, 1 target, 2 acoustic shadow
    labels/000000.json  one scene's labels; written last, so it marks the image complete
    labels.jsonl        all labels in index order, assembled when every image is done

Every file goes through a temp file and a rename, so a killed run leaves only complete
files; rerunning the same command skips complete images and renders the rest.
"""
from __future__ import annotations

import itertools
import json
import multiprocessing as mp
import os
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Iterator

import numpy as np

from tqdm import tqdm

from sasmi import __version__
from sasmi.errors import SasmiError
from sasmi.images import FORMATS, write_gray, write_text
from sasmi.labels import categories_of, read_labels
from sasmi.masks import write_class_mask, write_instance_mask
from sasmi.preprocess import check_size
from sasmi.scene import Preset

if TYPE_CHECKING:
    from sasmi.render.mitsuba import Rendered


@dataclass(frozen=True)
class RenderJob:
    preset: Preset
    out: Path
    count: int
    seed: int = 0
    size: int = 256
    spp: int = 16
    image_format: str = "png"
    workers: int = 1

    def validate(self) -> "RenderJob":
        if self.count <= 0:
            raise SasmiError(f"--count: {self.count} is not allowed (allowed: >= 1)")
        check_size(self.size, "--size")
        if self.spp <= 0:
            raise SasmiError(f"--spp: {self.spp} is not allowed (allowed: >= 1)")
        if self.workers <= 0:
            raise SasmiError(f"--workers: {self.workers} is not allowed (allowed: >= 1)")
        if self.image_format not in FORMATS:
            raise SasmiError(f"--format: {self.image_format!r} is not allowed (allowed: {', '.join(FORMATS)})")
        return self

    def run_record(self) -> dict:
        """What identifies the set: a resumed run must match it (the count may grow)."""
        return {"preset": self.preset.raw, "seed": self.seed, "size": self.size, "spp": self.spp,
                "format": self.image_format}


def _name(index: int) -> str:
    return f"{index:06d}"


def image_path(out: Path, index: int, image_format: str) -> Path:
    return out / "images" / (_name(index) + FORMATS[image_format])


def is_complete(out: Path, index: int, image_format: str) -> bool:
    return ((out / "labels" / f"{_name(index)}.json").is_file() and image_path(out, index, image_format).is_file()
            and (out / "masks" / f"{_name(index)}.png").is_file())


def write_one(out: Path, index: int, image: np.ndarray, rendered: Rendered, image_format: str) -> None:
    """Write one chip (image (H, W) in [0, 1]); its labels file goes last and marks the chip complete."""
    write_gray(image_path(out, index, image_format), image)
    write_class_mask(out / "masks" / f"{_name(index)}.png", rendered.mask)
    write_instance_mask(out / "instances" / f"{_name(index)}.png", rendered.instances)
    write_instance_mask(out / "shadows" / f"{_name(index)}.png", rendered.shadows)
    label = replace(rendered.label, index=index, image=f"images/{image_path(out, index, image_format).name}",
                    mask=f"masks/{_name(index)}.png")
    write_text(out / "labels" / f"{_name(index)}.json", label.dumps())


# -- worker process state (one Renderer per process, so the kernel compiles once) --------
_worker: dict = {}


def _init_worker(job: RenderJob, threads: int | None) -> None:
    from sasmi.render.mitsuba import Renderer

    renderer = Renderer(size=job.size, spp=job.spp)
    if threads:
        renderer.dr.set_thread_count(threads)
    _worker.update(job=job, renderer=renderer)


def _render_index(index: int):
    job: RenderJob = _worker["job"]
    return index, _worker["renderer"].render(job.preset.sample(job.seed, index))


def _rendered(job: RenderJob, todo: list[int]) -> Iterator[tuple[int, object]]:
    """(index, Rendered) for every index in todo, in order; rendered here or by worker processes."""
    if job.workers == 1 or len(todo) <= 1:
        _init_worker(job, None)
        yield from map(_render_index, todo)
        return
    threads = max(1, (os.cpu_count() or 1) // job.workers)
    ctx = mp.get_context("spawn")  # Dr.Jit's thread pool does not survive fork
    with ctx.Pool(job.workers, initializer=_init_worker, initargs=(job, threads)) as pool:
        yield from pool.imap(_render_index, todo)


def _check_run_record(job: RenderJob, identity: dict) -> None:
    from sasmi.render.llvm import versions

    run_json = job.out / "run.json"
    record = {**job.run_record(), **identity}
    if run_json.is_file():
        try:
            previous = json.loads(run_json.read_text())
        except (OSError, json.JSONDecodeError) as e:
            raise SasmiError(f"{run_json}: unreadable ({e}); choose another --out") from None
        if {k: previous.get(k) for k in record} != record:
            raise SasmiError(f"{job.out}: holds a render set made with other settings; choose another --out")
    elif job.out.exists() and any(job.out.iterdir()):
        raise SasmiError(f"{job.out}: exists and is not a render set; choose another --out")
    write_text(run_json, json.dumps({**record, "preset_path": str(job.preset.path or ""), "count": job.count,
                                     "sasmi": __version__, **versions()}, indent=2))


Transform = Callable[[np.ndarray], np.ndarray]  # (B, H, W) in [0, 1] -> (B, H, W) in [0, 1]


def render_set(job: RenderJob, transform: Transform | None = None, identity: dict | None = None,
               batch: int = 16, progress: bool = True) -> Path:
    """Render scenes 0..count-1 of the preset into job.out; returns job.out.

    `transform` (e.g. a GAN generator) maps each batch of rendered images before they are
    written; masks and labels are the render's. `identity` joins the run record, so a
    resumed run must use the same transform (e.g. the same generator checkpoint).
    """
    from sasmi.render.geometry import check_scene

    job = job.validate()
    for index in range(job.count):  # every scene is drawn and checked before anything is written
        check_scene(job.preset.sample(job.seed, index))
    _check_run_record(job, identity or {})
    for stale in job.out.glob("*/.*.tmp*"):  # temp files of a killed run; their targets were never renamed
        stale.unlink()
    todo = [i for i in range(job.count) if not is_complete(job.out, i, job.image_format)]
    with tqdm(total=job.count, initial=job.count - len(todo), unit="img", desc="render", disable=not progress,
              dynamic_ncols=True) as bar:
        stream = _rendered(job, todo)
        while chunk := list(itertools.islice(stream, batch if transform else 1)):
            images = np.stack([rendered.image for _, rendered in chunk])  # (B, H, W) in [0, 1]
            if transform is not None:
                images = transform(images)
            for (index, rendered), image in zip(chunk, images):
                write_one(job.out, index, image, rendered, job.image_format)
            bar.update(len(chunk))
    assemble_labels(job.out, job.count)
    return job.out


def assemble_labels(out: Path, count: int) -> None:
    lines = [(out / "labels" / f"{_name(i)}.json").read_text().strip() for i in range(count)]
    write_text(out / "labels.jsonl", "\n".join(lines) + "\n")
    # class ids for ATR tools (id = position + 1), known only once every chip is drawn
    run_json = out / "run.json"
    record = json.loads(run_json.read_text())
    record["categories"] = categories_of(read_labels(out))
    write_text(run_json, json.dumps(record, indent=2))

