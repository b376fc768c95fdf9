"""Retrain the reference weights sasmi ships (sasmi/weights/, model card docs/models.md), bit for bit.

    python benchmarks/reference_weights.py --chips ../shared/data/sonar-chips --out runs/reference --check
    python benchmarks/reference_weights.py ... --install    # and copy the three files into sasmi/weights/

Every stage trains a fixed number of steps from a fixed seed (not a time budget), on 2 torch
threads, so the same torch on the same kind of CPU writes the same bytes: --check compares each
file's SHA-256 with the shipped one (exit 1 if one differs). Rerunning resumes: a finished stage
is kept. Another --chips (a split's train side) trains the same recipe on those chips alone.

1. phi     the φ autoencoder on every chip (targets and seafloor of every sonar)
2. seabeds the seabed statistics of the seafloor chips of the targets' sonar, the speckle of the
           target chips' floors (sasmi.realism.seabeds)
3. renders the default preset, 400 chips at 128 px
4. floors  their targets on floors drawn from those seabeds (what `sasmi generate` lays them on)
5. sasgan  the SAS GAN, the default recipe, on every target chip
"""
from __future__ import annotations

import argparse
import hashlib
import os
import shutil
import sys
from pathlib import Path

STEPS = {"phi": 1200, "sasgan": 1200}
TINY = {"phi": 4, "sasgan": 4}  # --tiny: the same stages in seconds, for the test of bit-for-bit
SEED, SIZE, COUNT, PRESET = 0, 128, 400, "cylinder_chip"


def sonar_floors(chips: Path, out: Path) -> Path:
    """A folder of links to the seafloor chips of the sonar of the target chips (by the MANIFEST)."""
    from sasmi.atr.pools import sonars
    from sasmi.images import list_images

    sonar = sonars(chips) or {}
    wanted = {sonar.get(str(p.resolve())) for p in list_images(chips / "targets")} - {None}
    if out.is_dir():
        return out
    tmp = out.with_name(out.name + ".tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    for p in list_images(chips / "seafloor"):
        if not wanted or sonar.get(str(p.resolve())) in wanted:
            os.symlink(p.resolve(), tmp / p.name)
    tmp.rename(out)
    return out


def trained(kind, out: Path, overrides: dict, inputs: dict) -> Path:
    from sasmi.gan.loop import resolve_config, train
    import torch

    last = out / "checkpoints" / "last.pt"
    resume = last.is_file()
    cfg = resolve_config(kind, out, {"steps": overrides["steps"]} if resume else overrides, resume)
    if not resume or torch.load(last, weights_only=True)["step"] < cfg.steps:
        train(kind, cfg, out, inputs, torch.device("cpu"), resume)
    return out


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--chips", type=Path, required=True, help="the real chips: targets/, seafloor/, MANIFEST.csv")
    p.add_argument("--out", type=Path, required=True, help="a folder for the runs and RUN/weights/")
    p.add_argument("--tiny", action="store_true", help="a few steps at 32 px: checks that two runs agree bit for bit")
    p.add_argument("--check", action="store_true", help="compare with the shipped files; exit 1 if one differs")
    p.add_argument("--install", action="store_true", help="copy the weights into sasmi/weights/")
    args = p.parse_args()

    import torch

    torch.set_num_threads(2)  # the thread count changes the float sums' order, hence the bytes
    from sasmi.gan.kinds.autoencoder import AUTOENCODER
    from sasmi.gan.kinds.sasgan import SASGAN
    from sasmi.gan.recipes import DEFAULT, load_recipe
    from sasmi.gan.export_weights import export_weights
    from sasmi.realism.floors import onto_seabed_floors
    from sasmi.realism.seabeds import fit_seabeds, load_seabeds, save_seabeds
    from sasmi.renderset.write import RenderJob, render_set
    from sasmi.scene.preset import load_preset
    from sasmi.weights import FILES, HERE

    steps, size = (TINY, 32) if args.tiny else (STEPS, SIZE)
    count = 8 if args.tiny else COUNT
    out = args.out
    # what made them, with no path or time in it: the bytes must not depend on where the script ran
    about = {"chips": "the shared real chips (sasmi chips build --manifest sonar-chips)", "seed": SEED, "steps": steps,
             "size": size, "preset": PRESET, "renders": count, "recipe": DEFAULT}
    print("1/5 phi", flush=True)
    phi = trained(AUTOENCODER, out / "phi", {"steps": steps["phi"], "size": size, "seed": SEED}, {"real": args.chips})
    print("2/5 seabeds", flush=True)
    weights = out / "weights"
    seabeds = save_seabeds(fit_seabeds(sonar_floors(args.chips, out / "floors"), args.chips / "targets"),
                           weights / FILES["seabeds"], about)
    print("3/5 renders", flush=True)
    render_set(RenderJob(preset=load_preset(PRESET), out=out / "renders", count=count, seed=SEED, size=size))
    print("4/5 renders on drawn floors", flush=True)
    if not (out / "on_floors" / "labels.jsonl").is_file():
        onto_seabed_floors(out / "renders", load_seabeds(seabeds), out / "on_floors", size, SEED)
    print("5/5 sasgan", flush=True)
    gan = trained(SASGAN, out / "sasgan", {**load_recipe(DEFAULT), "steps": steps["sasgan"], "size": size, "seed": SEED},
                  {"real": args.chips / "targets", "renders": out / "on_floors", "phi": phi})

    made = {"phi": export_weights(phi, "autoencoder", weights / FILES["phi"], "best", about), "seabeds": seabeds,
            "sasgan": export_weights(gan, "sasgan", weights / FILES["sasgan"], "last", about)}
    same = True
    for name, path in made.items():
        digest = hashlib.sha256(path.read_bytes()).hexdigest()
        shipped = HERE / FILES[name]
        match = shipped.is_file() and hashlib.sha256(shipped.read_bytes()).hexdigest() == digest
        same &= match
        print(f"{name:7s} {path.stat().st_size / 1e6:5.2f} MB  sha256 {digest[:16]}"
              + (f"  {'the same as' if match else 'differs from'} the shipped file" if args.check else ""))
        if args.install:
            shutil.copyfile(path, shipped)
    return 1 if args.check and not same else 0


if __name__ == "__main__":
    sys.exit(main())
