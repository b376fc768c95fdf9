"""Does `sasmi fit-scene` pin roughness? Fits of seafloor roughness and albedo from three starts, by the
mean φ alone and by the φ distribution (means and spreads), against chips of a known preset (scenes the
fit never renders) and against real chips, where no truth is known but the ends of the three starts
should agree. Prints one row per fit; the figures of docs/results.md, *Differentiable scenes*.

    .venv/bin/python benchmarks/fit_scene_recovery.py --scenes 4 --real runs/split/train/seafloor --match 'milco_*'
    .venv/bin/python benchmarks/fit_scene_recovery.py --real runs/split/train/seafloor --match 'milco_*' --real-only
    .venv/bin/python benchmarks/fit_scene_recovery.py      # 8 scenes, as fit-scene's default
"""
from __future__ import annotations

import argparse
import fnmatch
import time

import numpy as np
import torch

from sasmi.eval.features import phi_features
from sasmi.gan.autoencoder import load_encoder
from sasmi.images import list_images
from sasmi.realism.fit_scene import FitConfig, fit_scene, scaled_preset
from sasmi.render.differentiable import DifferentiableRenderer, scene_parameters
from sasmi.scene.preset import Preset, load_preset

PARAMS = ("seafloor.roughness", "seafloor.albedo")


def truth_phi(encoder, preset: Preset, count: int, size: int, spp: int) -> np.ndarray:
    """φ of `count` renders of scenes 0.. of the preset at seed 1 (fits render seed 0's)."""
    renderer = DifferentiableRenderer(size, spp)
    with torch.no_grad():
        images = [renderer.image(renderer.bind(s), torch.tensor(scene_parameters(s)), 10_000 + k).numpy()
                  for k, s in enumerate(preset.sample(1, k) for k in range(count))]
    return phi_features(encoder, np.stack(images))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--preset", default="seafloor_only", help="the truth, and the start once its roughness is scaled")
    p.add_argument("--phi", default="sasmi/weights/phi.pt", help="φ encoder (default: the shipped one)")
    p.add_argument("--real", help="real chips to fit as well (no truth: the three starts should end alike)")
    p.add_argument("--match", default="*", help="only the real chips whose file names match (e.g. one sonar's)")
    p.add_argument("--starts", type=float, nargs="+", default=[0.3, 1.0, 3.0], help="start roughness / truth")
    p.add_argument("--steps", type=int, default=40)
    p.add_argument("--scenes", type=int, default=FitConfig().scenes)
    p.add_argument("--real-only", action="store_true", help="with --real: skip the fits against the preset's renders")
    p.add_argument("--spp", type=int, default=8)
    args = p.parse_args()
    torch.set_num_threads(1)
    encoder = load_encoder(args.phi)
    size = encoder.image_size
    preset = load_preset(args.preset)
    targets = {}
    if not (args.real and args.real_only):
        targets[f"{args.preset} renders"] = truth_phi(encoder, preset, 32, size, args.spp)
    if args.real:
        paths = [q for q in list_images(args.real) if fnmatch.fnmatch(q.name, args.match)]
        targets[f"{len(paths)} real chips ({args.match})"] = phi_features(encoder, paths)
    print(f"{args.steps} Adam steps, {args.scenes} scenes of {size} px, {args.spp} spp; scales of the truth "
          f"({args.preset}) for its renders, of {args.preset} for real chips", flush=True)
    for name, target in targets.items():
        for weight, loss in ((0.0, "mean φ"), (1.0, "φ distribution")):
            cfg = FitConfig(params=PARAMS, steps=args.steps, lr=0.1, scenes=args.scenes, size=size, spp=args.spp,
                            spread_weight=weight)
            for start in args.starts:
                began = time.perf_counter()
                initial = Preset.from_dict(scaled_preset(preset, {"seafloor.roughness": start}))
                result = fit_scene(initial, encoder, target, cfg, progress=False)
                print(f"{name:28s} {loss:15s} roughness x{start:<4g} → x{start * result.scales[PARAMS[0]]:.3f}, "
                      f"albedo x{result.scales[PARAMS[1]]:.3f}, loss {result.trajectory[0]['loss']:.3f} → "
                      f"{result.trajectory[-1]['loss']:.3f} ({time.perf_counter() - began:.0f} s)", flush=True)


if __name__ == "__main__":
    main()
