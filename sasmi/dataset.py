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

import json
import multiprocessing as mp
import os
from dataclasses import dataclass
from pathlib import Path

from tqdm import tqdm

from sasmi import __version__
from sasmi.errors import SasmiError
from sasmi.images import FORMATS, write_gray, write_mask, write_text
from sasmi.scene import Preset, Scene


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
        if self.size <= 0 or self.size % 16:
            raise SasmiError(f"--size: {self.size} is not allowed (allowed: a positive multiple of 16)")
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


def write_one(out: Path, index: int, seed: int, scene: Scene, rendered, image_format: str) -> None:
    write_gray(image_path(out, index, image_format), rendered.image)
    write_mask(out / "masks" / f"{_name(index)}.png", rendered.mask)
    labels = {"index": index, "seed": seed, "image": f"images/{image_path(out, index, image_format).name}",
              "mask": f"masks/{_name(index)}.png", **rendered.labels}
    write_text(out / "labels" / f"{_name(index)}.json", json.dumps(labels))


# -- worker process state (one Renderer per process, so the kernel compiles once) --------
_worker: dict = {}


def _init_worker(job: RenderJob, threads: int | None) -> None:
    from sasmi.mitsuba_render import Renderer

    renderer = Renderer(size=job.size, spp=job.spp)
    if threads:
        renderer.dr.set_thread_count(threads)
    _worker.update(job=job, renderer=renderer)


def _render_index(index: int) -> int:
    job: RenderJob = _worker["job"]
    scene = job.preset.sample(job.seed, index)
    write_one(job.out, index, job.seed, scene, _worker["renderer"].render(scene), job.image_format)
    return index


def _check_run_record(job: RenderJob) -> None:
    from sasmi.mitsuba_render import versions

    run_json = job.out / "run.json"
    record = job.run_record()
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


def render_set(job: RenderJob, progress: bool = True) -> Path:
    """Render scenes 0..count-1 of the preset into job.out; returns job.out."""
    job = job.validate()
    from sasmi.geometry import check_targets

    for index in range(job.count):  # every scene is drawn and checked before anything is written
        check_targets(job.preset.sample(job.seed, index))
    _check_run_record(job)
    for stale in job.out.glob("*/.*.tmp*"):  # temp files of a killed run; their targets were never renamed
        stale.unlink()
    todo = [i for i in range(job.count) if not is_complete(job.out, i, job.image_format)]
    bar = tqdm(total=job.count, initial=job.count - len(todo), unit="img", desc="render", disable=not progress,
               dynamic_ncols=True)
    with bar:
        if job.workers == 1 or len(todo) <= 1:
            _init_worker(job, None)
            for index in todo:
                _render_index(index)
                bar.update()
        else:
            threads = max(1, (os.cpu_count() or 1) // job.workers)
            ctx = mp.get_context("spawn")  # Dr.Jit's thread pool does not survive fork
            with ctx.Pool(job.workers, initializer=_init_worker, initargs=(job, threads)) as pool:
                for _ in pool.imap_unordered(_render_index, todo):
                    bar.update()
    assemble_labels(job.out, job.count)
    return job.out


def assemble_labels(out: Path, count: int) -> None:
    lines = [(out / "labels" / f"{_name(i)}.json").read_text().strip() for i in range(count)]
    write_text(out / "labels.jsonl", "\n".join(lines) + "\n")


def read_labels(out: str | Path) -> list[dict]:
    path = Path(out) / "labels.jsonl"
    try:
        return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    except (OSError, json.JSONDecodeError) as e:
        raise SasmiError(f"{path}: cannot read labels ({e})") from None
