"""`sasmi generate PRESET --count N --out DIR`: render and translate, streamed.

Render scenes 0..N-1 of a preset and pass each batch through a SAS GAN generator; writes a render
set (images/, masks/, labels.jsonl, run.json) whose images are the translations. Rerunning the same
command resumes. With no --generator, the shipped one (docs/models.md) translates renders laid on
floors drawn from the shipped seabeds, as it was trained; --floors lays them on real floor chips.
"""
from __future__ import annotations

import argparse
import hashlib
from pathlib import Path

from sasmi.cli.common import add_translation_flags, generator_from


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("generate", help="render scenes and translate them with a trained SAS GAN, labels kept",
                       description=__doc__)
    p.add_argument("preset", type=Path, help="scene preset (TOML)")
    p.add_argument("--count", type=int, default=16, help="number of scenes")
    p.add_argument("--out", type=Path, required=True, help="the render set to write (images are the translations)")
    p.add_argument("--seed", type=int, default=0, help="scene i depends only on (seed, i)")
    p.add_argument("--size", type=int, help="render size, a multiple of 16 (default: the size the generator "
                                            "was trained at; another size is resampled to it and back)")
    p.add_argument("--spp", type=int, default=16, help="samples per pixel")
    p.add_argument("--workers", type=int, default=1,
                   help="processes, each rendering and translating every N-th scene on cores // N threads "
                        "(default: 1; on 2 cores 2 make 1.25 × the chips per second: docs/scale.md)")
    p.add_argument("--floors", metavar="DIR",
                   help="lay each render's target and shadow on a real seafloor chip first, as `sasmi fit --floors` "
                        "did for the generator it trained (needs --real); without it, the shipped generator's renders "
                        "take floors drawn from the shipped seabeds, another generator's keep their own")
    p.add_argument("--seabeds", metavar="FILE",
                   help="lay each render's target and shadow on a floor drawn from this seabeds file "
                        "(benchmarks/reference_weights.py writes one; default with the shipped generator: the "
                        "shipped seabeds)")
    p.add_argument("--real", metavar="DIR", help="with --floors: the real target chips the floors are matched to "
                                                  "(the --real of that `sasmi fit`)")
    add_translation_flags(p, shipped=True)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    job, generator, identity, floor_of, relabel = _setup(args)
    if job.workers > 1:
        from functools import partial

        from sasmi.renderset.processes import complete_chips, run_shares
        from sasmi.renderset.write import missing, prepare

        prepare(job, identity)  # every scene checked and run.json written before any process starts
        del generator
        run_shares(partial(_share, args), job.workers, partial(complete_chips, job.out), job.count, "generate")
        unfinished = missing(job.out, job.count, job.image_format)
        if unfinished:  # claimed by another command rendering into the same folder
            print(f"{len(unfinished)} chips of {args.out} are another process's to finish; rerun the same command "
                  "once it stops if any are left")
            return 0
    else:
        _generate(args, job, generator, identity, floor_of, relabel)
    which = f"the generator {args.generator}" if args.generator else "the shipped generator"
    print(f"wrote {args.count} translated chips ({job.size} px) with masks and labels to {args.out}, by {which}")
    return 0


def _setup(args: argparse.Namespace):
    """Check every flag and load what the chips need: (job, generator, identity, floor_of, relabel)."""
    from sasmi.renderset.write import RenderJob
    from sasmi.errors import SasmiError
    from sasmi.images import list_images
    from sasmi.scene.preset import load_preset

    if bool(args.floors) != bool(args.real):
        raise SasmiError("--floors and --real: give both (the floors are matched to the real target chips) or neither")
    if args.floors and args.seabeds:
        raise SasmiError("--floors and --seabeds: real floor chips or drawn seabeds, not both")
    for flag, folder in (("--floors", args.floors), ("--real", args.real)):
        if folder and not list_images(folder):
            raise SasmiError(f"{flag} {folder}: no image (png, jpg, tif, tiff, npy) in it")
    preset = load_preset(args.preset)
    generator = generator_from(args)
    job = RenderJob(preset=preset, out=args.out, count=args.count, seed=args.seed,
                    size=args.size or generator.image_size, spp=args.spp, workers=args.workers).validate()
    identity = {"generator": str(Path(args.generator or generator.checkpoint).resolve()),
                "generator_sha256": hashlib.sha256(generator.checkpoint.read_bytes()).hexdigest()}
    recorded, floor_of, relabel = floor_source(args, job.size)
    identity.update(recorded)
    return job, generator, identity, floor_of, relabel


def _generate(args: argparse.Namespace, job, generator, identity: dict, floor_of, relabel,
              progress: bool = True) -> None:
    """Render and translate the job's scenes in this process."""
    import numpy as np

    from sasmi.gan.translate import translate
    from sasmi.realism.floors import FloorsAhead, on_floor
    from sasmi.renderset.write import render_set

    # once a batch is translated, the next batch's floors are drawn while it is written and the next renders
    floors = FloorsAhead(floor_of, job.indices(), args.batch) if relabel else None

    def transform(images, masks, indices):  # (B, H, W) in [0, 1], (B, H, W) uint8 -> (B, H, W) in [0, 1]
        if floors is not None:
            images = np.stack([on_floor(image, mask, floors(i)) for image, mask, i in zip(images, masks, indices)])
        # a tone style's code per chip from (--seed, scene index), as its scene: the same in any batch or process
        translated = translate(generator, images, args.batch, seeds=[args.seed * 2 ** 32 + i for i in indices])
        if floors is not None:
            floors.draw_after(max(indices))
        return translated

    try:
        render_set(job, transform=transform, identity=identity, batch=args.batch, relabel=relabel, progress=progress)
    finally:
        if floors is not None:
            floors.close()


def _share(args: argparse.Namespace, share: int, shares: int) -> None:
    """One process of `--workers N`: the scenes with index % N == share, rendered and translated on
    cores // N threads (torch's: --threads where given)."""
    from dataclasses import replace

    from sasmi.renderset.processes import in_share
    from sasmi.renderset.threads import local_threads

    threads = local_threads(shares)
    args = argparse.Namespace(**{**vars(args), "workers": 1, "threads": args.threads or threads})

    def body() -> None:
        job, generator, identity, floor_of, relabel = _setup(args)
        _generate(args, replace(job, shard=(share, shares)), generator, identity, floor_of, relabel, progress=False)

    in_share("generate", threads, body)


def floor_source(args: argparse.Namespace, size: int):
    """What each render is laid on before the generator: (what the set's identity records, floor_of(i),
    relabel(label, i)), or ({}, None, None) to translate the renders as they are."""
    from sasmi.realism.floors import floor_for, floor_label, matching_floors, seabed_floor, seabed_floor_label

    if args.floors:
        floors = matching_floors(args.floors, args.real, size)
        return ({"floors": sorted({str(Path(f).resolve()) for f in floors})},
                lambda i: floor_for(floors, args.seed, i, size),
                lambda label, i: floor_label(label, floors, args.seed, i))
    if args.seabeds or args.generator is None:  # the shipped generator learned from renders on drawn seabeds
        from sasmi.realism.seabeds import load_seabeds
        from sasmi.weights import shipped

        seabeds = load_seabeds(args.seabeds or shipped("seabeds"))
        return ({"seabeds_sha256": hashlib.sha256(seabeds.path.read_bytes()).hexdigest()},
                lambda i: seabed_floor(seabeds, (size, size), args.seed, i),
                lambda label, i: seabed_floor_label(label, seabeds, args.seed, i))
    return {}, None, None
