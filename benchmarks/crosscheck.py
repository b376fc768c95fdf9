"""Mitsuba against POV-Ray render time for the same scene, measured in one run, as a ratio.

cylinder_chip scene 0 at 256², each renderer as `sasmi crosscheck` runs it: Mitsuba's
`direct` integrator at crosscheck.SPP samples per pixel, one emitter sampled per sample;
POV-Ray tracing every light from 3 x 3 jittered sub-pixel rays plus the centre ray
(povray.ANTIALIAS), and from 1 ray per pixel for reference. Mitsuba "cold" is a fresh
Renderer (scene load and JIT compile included), "warm" the median of 3 further renders;
POV-Ray times are the whole `povray` process (start, parse of the meshes, trace).

    .venv/bin/python benchmarks/crosscheck.py [--size 256] [--emitters 1 8 32]
"""
from __future__ import annotations

import argparse
import dataclasses
import os
import platform
import statistics
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PRESET = REPO / "scenes" / "cylinder_chip.toml"


def mitsuba_seconds(scene, size: int, spp: int) -> tuple[float, float]:
    from sasmi.render.geometry import build_geometry
    from sasmi.render.mitsuba import Renderer

    g = build_geometry(scene, size)
    start = time.perf_counter()
    renderer = Renderer(size=size, spp=spp)
    renderer.prepare(g)
    renderer.radiance(scene.seed)
    cold = time.perf_counter() - start
    warm = []
    for seed in range(3):
        start = time.perf_counter()
        renderer.radiance(seed)
        warm.append(time.perf_counter() - start)
    return cold, statistics.median(warm)


def povray_seconds(scene, size: int) -> tuple[float, float]:
    from sasmi.render import crosscheck, povray
    from sasmi.render.geometry import build_geometry

    g = build_geometry(scene, size)
    sdl = povray.geometry_sdl(g)
    exposure = crosscheck.EXPOSURE_MARGIN / povray.radiance_bound(g)
    _, antialiased = povray.radiance(sdl, size, exposure)
    _, single = povray.run(sdl, size, [f"Declare=Exposure={exposure:.9g}"])
    return antialiased, single


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--emitters", type=int, nargs="+", default=[1, 8, 32])
    args = ap.parse_args()

    from sasmi.render import crosscheck, povray
    from sasmi.scene.preset import load_preset

    base = load_preset(PRESET).sample(0, 0)
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores; {povray.version()}")
    print(f"{PRESET.name} scene 0 at {args.size}x{args.size}; Mitsuba {crosscheck.SPP} spp, "
          f"POV-Ray {' '.join(povray.ANTIALIAS)}")
    print(f"{'emitters':>8} {'Mitsuba cold':>13} {'Mitsuba warm':>13} {'POV-Ray':>9} {'POV-Ray 1 ray/px':>17} "
          f"{'POV-Ray / Mitsuba warm':>23}")
    ratio = 0.0
    for n in args.emitters:
        scene = dataclasses.replace(base, sonar=dataclasses.replace(base.sonar, emitters=n))
        cold, warm = mitsuba_seconds(scene, args.size, crosscheck.SPP)
        antialiased, single = povray_seconds(scene, args.size)
        ratio = antialiased / warm
        print(f"{n:>8} {cold:>12.2f}s {warm:>12.2f}s {antialiased:>8.2f}s {single:>16.2f}s {ratio:>22.1f}x")
    print(f"ratio: POV-Ray takes {ratio:.1f}x Mitsuba's (warm) time for the same {args.size}² scene "
          f"with {args.emitters[-1]} emitters")


if __name__ == "__main__":
    main()
