"""Writes a render set: images/, masks/, labels.jsonl, run.json — atomically, resumably, concurrently.

Layout of OUT:
    run.json            resolved preset, seed, size, spp, format, versions (written first)
    images/000000.png   8-bit gray (or .tiff 16-bit, .npy float32)
    masks/000000.png    0 seafloor, 1 target, 2 acoustic shadow
    instances/, shadows/ per-target id masks (sasmi.masks)
    labels/000000.json  one scene's labels; written last, so it marks the image complete
    labels.jsonl        all labels in index order, assembled when every image is done
    claims/             who renders which chip now (sasmi.renderset.claims); gone when the set is complete

Every file goes through a temp file and a rename, so a killed run leaves only complete
files; rerunning the same command skips complete images and renders the rest. Any number
of processes (`--shard I/N`, or the same command started twice, on one host or many) may
render into one folder: each chip is claimed before it is rendered, so none is rendered twice.
"""
from __future__ import annotations

import itertools
import json
import os
import threading
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Iterator

import numpy as np

from tqdm import tqdm

from sasmi import __version__
from sasmi.renderset.claims import Claims
from sasmi.renderset.order import RENDER_WINDOW, grouped
from sasmi.errors import SasmiError
from sasmi.images import FORMATS, TEMPORARIES, check_room, write_gray, write_text
from sasmi.labels import ChipLabel, categories_of, read_labels
from sasmi.limits import FLAGS
from sasmi.masks import write_class_mask, write_instance_mask
from sasmi.preprocess import check_size
from sasmi.scene.preset import Preset

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
    image_format: str = "png"  # a key of sasmi.images.FORMATS, or "wds" (sasmi.renderset.shards)
    workers: int = 1  # > 1: a local Dask cluster of this many processes
    shard: tuple[int, int] = (0, 1)  # (I, N): only scenes with index % N == I (tar shards k % N == I for wds)
    scheduler: str | None = None  # tcp://HOST:PORT of a running Dask scheduler
    per_shard: int = 1000  # samples per tar shard (wds only)

    def validate(self) -> "RenderJob":
        FLAGS["--count"].check(self.count, "--count")
        check_size(self.size, "--size")
        FLAGS["--spp"].check(self.spp, "--spp")
        FLAGS["--workers"].check(self.workers, "--workers")
        if self.image_format not in (*FORMATS, "wds"):
            raise SasmiError(f"--format: {self.image_format!r} is not allowed (allowed: {', '.join(FORMATS)}, wds)")
        i, n = self.shard
        if not 0 <= i < n:
            raise SasmiError(f"--shard: {i}/{n} is not allowed (allowed: I/N with 0 <= I < N)")
        if self.scheduler and self.workers > 1:
            raise SasmiError("--scheduler and --workers: give one (the cluster at --scheduler has its own workers)")
        if self.per_shard < 1:
            raise SasmiError(f"--per-shard: {self.per_shard} is not allowed (allowed: >= 1)")
        return self

    def indices(self) -> list[int]:
        """The scenes this process renders (a folder's set is always 0..count-1)."""
        i, n = self.shard
        if self.image_format != "wds":
            return list(range(i, self.count, n))
        shards = range(i, -(-self.count // self.per_shard), n)
        return [x for k in shards for x in range(k * self.per_shard, min((k + 1) * self.per_shard, self.count))]

    def run_record(self) -> dict:
        """What identifies the set: a resumed run, and every shard, must match it (the count may grow)."""
        record = {"preset": self.preset.raw, "seed": self.seed, "size": self.size, "spp": self.spp,
                  "format": self.image_format}
        return {**record, "per_shard": self.per_shard} if self.image_format == "wds" else record


def _name(index: int) -> str:
    return f"{index:06d}"


def image_path(out: Path, index: int, image_format: str) -> Path:
    return out / "images" / (_name(index) + FORMATS[image_format])


def chip_bytes(size: int, image_format: str) -> int:
    """A generous estimate of one chip's files: the image (speckle barely compresses), three masks, the label."""
    return size * size * {"tiff16": 2, "npy": 4}.get(image_format, 1) + 3 * size * size // 4 + 4096


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


# -- rendering a chip: here, in a worker process, or on a Dask worker -------------------
_render_lock = threading.Lock()  # a Dask worker with several threads shares one Renderer per process


def render_chip(job: RenderJob, index: int, write: bool = True, threads: int | None = None) -> Rendered | None:
    """Render scene `index`; write it (and return None) or return it. One Renderer per (size, spp) per
    process, so the kernel compiles once; `threads` sizes this process's Dr.Jit pool."""
    from sasmi.render.mitsuba import renderer_for

    with _render_lock:
        renderer = renderer_for(job.size, job.spp)
        if threads and renderer.dr.thread_count() != threads:
            renderer.dr.set_thread_count(threads)
        rendered = renderer.render(job.preset.sample(job.seed, index))
    if not write:
        return rendered
    write_one(job.out, index, rendered.image, rendered, job.image_format)
    return None


Task = Callable[..., object]


def run_tasks(job: RenderJob, task: Task, items: list, claim: Callable[[object], bool], **kwargs) -> Iterator:
    """(item, task(job, item, threads=..., **kwargs)) for each item of `items` that `claim` grants, in
    completion order: in this process (workers 1), on a local Dask cluster (workers N) or on the
    cluster at --scheduler (the commands' --workers N starts whole processes: sasmi.renderset.processes)."""
    if job.scheduler is None and (job.workers == 1 or len(items) <= 1):  # a cluster would only cost its start
        for item in items:
            if claim(item):
                yield item, task(job, item, **kwargs)
        return
    from sasmi.renderset.cluster import dask_client, stream
    from sasmi.renderset.threads import local_threads

    workers = min(job.workers, len(items))
    threads = None if job.scheduler else local_threads(workers)
    remote = replace(job, out=job.out.resolve())  # workers may run elsewhere, in another folder
    with dask_client(job.scheduler, workers) as client:
        yield from stream(client, task, remote, items, claim, threads, **kwargs)


# -- the run record -------------------------------------------------------------------------
def _create_exclusively(path: Path, text: str) -> bool:
    """Write `path` whole if it does not exist yet (one of several starting processes wins)."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.new")
    try:
        tmp.write_text(text)
        os.link(tmp, path)
        return True
    except FileExistsError:
        return False
    except OSError as e:
        raise SasmiError(f"{path}: cannot write ({e.strerror or e}); nothing was written") from None
    finally:
        tmp.unlink(missing_ok=True)


def nothing_done(out: Path) -> bool:
    return not any(itertools.chain((out / "labels").glob("*.json"), (out / "shards").glob("*.tar")))


def check_run_record(job: RenderJob, identity: dict) -> None:
    """Write run.json before any chip, or check that an existing one has these settings.

    A folder whose run.json differs but that holds no complete chip (a run that failed before
    its first chip) takes the new settings; one with complete chips refuses them."""
    from sasmi.render.llvm import versions

    run_json = job.out / "run.json"
    record = {**job.run_record(), **identity}
    if not run_json.is_file() and job.out.is_dir() and any(not p.name.startswith(".") for p in job.out.iterdir()):
        raise SasmiError(f"{job.out}: exists and is not a render set; choose another --out")
    full = {**record, "preset_path": str(job.preset.path or ""), "count": job.count, "sasmi": __version__,
            **versions()}
    job.out.mkdir(parents=True, exist_ok=True)
    if _create_exclusively(run_json, json.dumps(full, indent=2)):
        return
    try:
        previous = json.loads(run_json.read_text())
    except (OSError, json.JSONDecodeError) as e:
        raise SasmiError(f"{run_json}: unreadable ({e}); choose another --out") from None
    if {k: previous.get(k) for k in record} == record:
        if previous.get("count") != job.count:
            write_text(run_json, json.dumps({**previous, "count": job.count}, indent=2))
    elif nothing_done(job.out):
        write_text(run_json, json.dumps(full, indent=2))
    else:
        raise SasmiError(f"{job.out}: holds a render set made with other settings; choose another --out")


def prepare(job: RenderJob, identity: dict | None = None) -> tuple[RenderJob, dict[int, tuple]]:
    """Check the job and every scene it will draw, then the run record; nothing is written before.
    Returns the job and each scene's structure (`sasmi.render.geometry.scene_structure`)."""
    from sasmi.render.geometry import check_scene, scene_structure

    job = job.validate()
    structures = {}
    for index in job.indices():
        scene = job.preset.sample(job.seed, index)
        check_scene(scene)
        structures[index] = scene_structure(scene)
    check_run_record(job, identity or {})
    return job, structures


def _temp_files(out: Path) -> dict[int, list[Path]]:
    """Temp files of killed writers, by chip index; removed by whoever claims the chip next."""
    found: dict[int, list[Path]] = {}
    for sub in ("images", "masks", "instances", "shadows", "labels"):
        for path in (out / sub).glob(TEMPORARIES):
            stem = path.name[1:].split(".", 1)[0]
            if stem.isdigit():
                found.setdefault(int(stem), []).append(path)
    return found


# (B, H, W) in [0, 1] and the B chips' scene indices (the seeds of anything random) -> (B, H, W) in [0, 1]
Transform = Callable[[np.ndarray, np.ndarray, list[int]], np.ndarray]  # (images, masks, scene indices) -> images


def render_set(job: RenderJob, transform: Transform | None = None, identity: dict | None = None,
               batch: int = 16, progress: bool = True,
               relabel: Callable[[ChipLabel, int], ChipLabel] | None = None) -> Path:
    """Render this job's scenes (0..count-1, or its --shard) into job.out; returns job.out.

    Other processes may render into the same folder at the same time: each chip is claimed
    first (sasmi.renderset.claims), and labels.jsonl is assembled by whoever finds every chip complete.
    `transform` (e.g. a GAN generator) maps each batch of rendered images before they are
    written; masks are the render's, and so are labels but for what `relabel` (label, scene
    index) changes, as a transform that replaces the floor must. `identity` joins the run
    record, so a resumed run must use the same transform (e.g. the same generator checkpoint).
    """
    if relabel is not None and transform is None:
        raise ValueError("render_set: relabel goes with a transform (untransformed chips are written by the workers)")
    if transform is not None and (job.workers > 1 or job.scheduler):
        raise ValueError("render_set: a transform runs in this process, so its job has one worker "
                         "(sasmi.renderset.processes runs several whole processes)")
    indices = job.indices()
    todo = [i for i in indices if not is_complete(job.out, i, job.image_format)]
    check_room(job.out, len(todo) * chip_bytes(job.size, job.image_format), f"{len(todo)} chips")
    job, structures = prepare(job, identity)
    todo = grouped(todo, structures, batch if transform else RENDER_WINDOW)
    claims = Claims(job.out / "claims")
    temps = _temp_files(job.out)

    def claim(index: int) -> bool:
        if not claims.take(_name(index)):
            return False
        if is_complete(job.out, index, job.image_format):  # finished since we looked
            claims.release(_name(index))
            return False
        for path in temps.pop(index, ()):
            path.unlink(missing_ok=True)
        return True

    with tqdm(total=len(indices), initial=len(indices) - len(todo), unit="img", desc="render",
              disable=not progress, dynamic_ncols=True) as bar, claims.kept_alive():
        stream = run_tasks(job, render_chip, todo, claim, write=transform is None)
        try:
            while chunk := list(itertools.islice(stream, batch if transform else 1)):
                if transform is not None:
                    images = transform(np.stack([rendered.image for _, rendered in chunk]),  # (B, H, W) in [0, 1]
                                       np.stack([rendered.mask for _, rendered in chunk]),   # (B, H, W) uint8
                                       [index for index, _ in chunk])
                    for (index, rendered), image in zip(chunk, images):
                        if relabel is not None:
                            rendered = replace(rendered, label=relabel(rendered.label, index))
                        write_one(job.out, index, image, rendered, job.image_format)
                for index, _ in chunk:
                    claims.release(_name(index))
                bar.update(len(chunk))
        finally:
            stream.close()  # on an error: cancels the cluster's tasks and closes a local cluster now
            claims.release_all()
    if not missing(job.out, job.count, job.image_format):
        assemble_labels(job.out, job.count)
        claims.remove_folder()
    return job.out


def missing(out: Path, count: int, image_format: str) -> list[int]:
    """Indices of scenes 0..count-1 without a complete chip (rendered by others, or not yet)."""
    return [i for i in range(count) if not is_complete(out, i, image_format)]


def assemble_labels(out: Path, count: int) -> None:
    lines = [(out / "labels" / f"{_name(i)}.json").read_text().strip() for i in range(count)]
    write_text(out / "labels.jsonl", "\n".join(lines) + "\n")
    # class ids for ATR tools (id = position + 1), known only once every chip is drawn
    run_json = out / "run.json"
    record = json.loads(run_json.read_text())
    record["categories"] = categories_of(read_labels(out), record.get("preset"))
    write_text(run_json, json.dumps(record, indent=2))

