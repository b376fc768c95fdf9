"""Render speed and memory: ms/image at 256², 32 emitters, 16 spp (labels and PNG writing
included), median over >= 20 images after warm-up, wall and CPU time (all threads); the same rays
cast by Mitsuba alone, and the render's scene update and launch, for the ratio; POV-Ray's
time for the first of those scenes, as `sasmi crosscheck` traces it, beside it; the throughput
of `sasmi render` itself in ms/chip with --workers 1 and 2 (the chips of a long run over the
chips of a short one, so start-up and compilation cancel); and peak RSS of `sasmi render` for
--count 10 vs --count 1000 (memory must stay flat in the count); and `sasmi generate`'s chips/s at 128²
with the shipped files, timed the same way.

    .venv/bin/python benchmarks/render.py [--images 24] [--workers 1 2] [--rss-counts 10 1000] [--generate 50 350] [--no-povray]

--avx2 times the in-process render with Dr.Jit's kernels compiled for AVX2 (8 float lanes) on an AVX-512
machine: what the vector width alone costs a machine without AVX-512 (Embree, Mitsuba's ray tracer, keeps
the machine's own instructions).
"""
from __future__ import annotations

import argparse
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PRESET = REPO / "scenes" / "cylinder_chip.toml"

RSS_CHILD = """
import resource, sys
from sasmi.cli.main import main
code = main(sys.argv[1:])
print("PEAK_RSS_KB", resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
sys.exit(code)
"""


def per_image_ms(images: int, warmup: int, size: int, spp: int) -> tuple[list[float], list[float]]:
    """Wall and CPU (all threads) milliseconds per image; CPU time is steadier on a shared machine."""
    from sasmi.renderset.write import write_one
    from sasmi.render.mitsuba import Renderer
    from sasmi.scene.preset import load_preset

    preset = load_preset(PRESET)
    renderer = Renderer(size=size, spp=spp)
    times, cpu = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(warmup + images):
            start, start_cpu = time.perf_counter(), time.process_time()
            rendered = renderer.render(preset.sample(0, i))
            write_one(Path(tmp), i, rendered.image, rendered, "png")
            times.append((time.perf_counter() - start) * 1000)
            cpu.append((time.process_time() - start_cpu) * 1000)
    return times[warmup:], cpu[warmup:]


def ray_cast_ms(size: int, spp: int, repeats: int = 5) -> tuple[float, float, float]:
    """(ray cast, scene update, launch) ms on the first scene, the best of `repeats` after a warm-up.

    Ray cast: the render's primary rays (size² x spp, straight down through the chip) and one shadow ray from
    each hit to one of the 32 emitters, traced by Mitsuba's ray tracer in this process in two passes, nothing
    else computed: the machine's own rate for those rays. The render's launch fuses its rays with light sampling
    and the film in one kernel; the scene update is what a new chip costs before it (Embree rebuilds its BVH)."""
    import numpy as np

    from sasmi.render.geometry import build_geometry
    from sasmi.render.mitsuba import Renderer
    from sasmi.render.visibility import CAMERA_HEIGHT, aligned
    from sasmi.scene.preset import load_preset

    renderer = Renderer(size=size, spp=spp)
    g = build_geometry(load_preset(PRESET).sample(0, 0), size)
    renderer.prepare(g)
    mi, dr, scene = renderer.mi, renderer.dr, renderer.mitsuba_scene
    rng = np.random.default_rng(0)
    n = size * size * spp
    # pixel by pixel, row-major, each pixel's samples together, as the render's sampler orders them
    cells = (np.arange(n) // spp).astype(np.float64)
    x = 2.0 * (cells % size + rng.uniform(0.0, 1.0, n)) / size - 1.0
    y = 2.0 * (cells // size + rng.uniform(0.0, 1.0, n)) / size - 1.0
    lights = g.emitter_positions[rng.integers(len(g.emitter_positions), size=n)]
    origin = mi.Point3f(aligned(x), aligned(y), aligned(np.full(n, CAMERA_HEIGHT)))
    light = mi.Point3f(*(aligned(lights[:, k]) for k in range(3)))
    dr.eval(origin, light)

    def best(f) -> float:
        times = []
        for _ in range(repeats + 1):
            start = time.perf_counter()
            f()
            times.append((time.perf_counter() - start) * 1000)
        return min(times[1:])

    update = best(lambda: (renderer.prepare(g), dr.sync_thread()))
    launch = best(lambda: renderer.collect(renderer.launch(0)))

    def cast() -> None:
        down = mi.Vector3f(0, 0, -1)
        hit = origin + down * scene.ray_intersect_preliminary(mi.Ray3f(origin, down)).t
        towards = light - hit
        distance = dr.norm(towards)
        blocked = scene.ray_test(mi.Ray3f(hit + 1e-4 * towards / distance, towards / distance, distance * 0.999))
        dr.eval(blocked)
        dr.sync_thread()

    return best(cast), update, launch


def povray_ms(scene, size: int) -> tuple[float, float]:
    """Wall and CPU milliseconds of the `povray` process rendering `scene` as the cross-check does."""
    import resource

    from sasmi.render import crosscheck, povray
    from sasmi.render.geometry import build_geometry

    g = build_geometry(scene, size)
    sdl = povray.geometry_sdl(g)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    _, seconds = povray.radiance(sdl, size, crosscheck.EXPOSURE_MARGIN / povray.radiance_bound(g))
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime
    return seconds * 1000, cpu * 1000


def peak_rss_mb(count: int, size: int) -> tuple[float, float]:
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        proc = subprocess.run([sys.executable, "-c", RSS_CHILD, "render", str(PRESET), "--count", str(count),
                               "--out", str(Path(tmp) / "set"), "--size", str(size)],
                              capture_output=True, text=True, check=True)
        seconds = time.perf_counter() - start
    kb = int(proc.stdout.split("PEAK_RSS_KB")[1].split()[0])
    return kb / 1024, seconds


def command_seconds(command: str, count: int, size: int, workers: int, repo: Path = REPO) -> float:
    """Wall seconds of `sasmi COMMAND` (render, or generate with the shipped files) making `count` chips, run in
    `repo` (whose package `python -m sasmi` imports)."""
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        subprocess.run([sys.executable, "-m", "sasmi", command, str(repo / PRESET.relative_to(REPO)), "--count",
                        str(count), "--out", str(Path(tmp) / "set"), "--size", str(size), "--workers", str(workers)],
                       capture_output=True, text=True, check=True, cwd=repo)
        return time.perf_counter() - start


def throughput_ms(command: str, workers: int, size: int, short: int, long: int, repo: Path = REPO) -> float:
    """ms per chip of `sasmi COMMAND --workers N`: (time of `long` chips - time of `short`) / (long - short)."""
    seconds = [command_seconds(command, count, size, workers, repo) for count in (long, short)]
    return (seconds[0] - seconds[1]) / (long - short) * 1000


def compile_for_avx2() -> str:
    """Make Dr.Jit's LLVM backend compile every later kernel for AVX2 at 8 float lanes, through its C API's
    jit_llvm_set_target (not bound in Python); returns the target it then reports."""
    import ctypes

    from sasmi.render.llvm import import_mitsuba

    _, dr = import_mitsuba()
    dr.eval(dr.llvm.Float(1.0) + 1.0)  # the backend starts on its first kernel
    core = ctypes.CDLL(str(Path(dr.__file__).parent / "libdrjit-core.so"))
    core._Z21jit_llvm_vector_widthv.restype = ctypes.c_uint32
    core._Z19jit_llvm_target_cpuv.restype = ctypes.c_char_p
    core._Z19jit_llvm_set_targetPKcS0_j(b"haswell", b"+avx,+avx2,+fma,+f16c,-avx512f,-avx512vl,-avx512bw,-avx512dq", 8)
    return f"{core._Z19jit_llvm_target_cpuv().decode()}, {core._Z21jit_llvm_vector_widthv()} float lanes"


def cpu_description() -> str:
    """The CPU's model and the vector width Dr.Jit's LLVM backend compiles for: 16 float lanes with
    AVX-512, 8 with AVX2 (--avx2 measures what the narrower width costs)."""
    model, flags = platform.processor() or platform.machine(), set()
    try:
        for line in open("/proc/cpuinfo"):
            key, _, value = line.partition(":")
            if key.strip() == "model name":
                model = value.strip()
            elif key.strip() == "flags":
                flags = set(value.split())
                break
    except OSError:
        pass
    width = "AVX-512, 16 float lanes" if "avx512f" in flags else "AVX2, 8 float lanes" if "avx2" in flags else "no AVX2"
    return f"{model} ({width}), {os.cpu_count()} cores"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--images", type=int, default=24)
    ap.add_argument("--warmup", type=int, default=3)
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--workers", type=int, nargs="*", default=[1, 2], help="render processes to time sasmi render with")
    ap.add_argument("--chips", type=int, nargs=2, default=[16, 96], metavar=("SHORT", "LONG"),
                    help="the two run lengths whose difference is timed (default 16 96)")
    ap.add_argument("--generate", type=int, nargs=2, default=[50, 350], metavar=("SHORT", "LONG"),
                    help="the run lengths whose difference times `sasmi generate` at 128² with the shipped files, "
                         "with each of --workers (default 50 350; 0 0 skips it)")
    ap.add_argument("--rss-counts", type=int, nargs="*", default=[10, 1000])
    ap.add_argument("--rss-size", type=int, default=256)
    ap.add_argument("--no-povray", action="store_true", help="skip the POV-Ray timing (no povray installed)")
    ap.add_argument("--avx2", action="store_true", help="Dr.Jit's kernels for AVX2 (8 lanes) in the in-process render")
    args = ap.parse_args()

    print(f"machine: {cpu_description()}, Python {platform.python_version()}")
    if args.avx2:
        print(f"Dr.Jit compiles for: {compile_for_avx2()} (Embree: the machine's own)")
    times, cpu = per_image_ms(args.images, args.warmup, args.size, args.spp)
    q = statistics.quantiles(times, n=10)
    print(f"render {args.size}x{args.size}, 32 emitters, {args.spp} spp, labels + PNG: "
          f"median {statistics.median(times):.0f} ms/image (p10 {q[0]:.0f}, p90 {q[-1]:.0f}, "
          f"mean {statistics.mean(times):.0f}; {len(times)} images); "
          f"CPU median {statistics.median(cpu):.0f}, mean {statistics.mean(cpu):.0f} ms/image")
    rays, update, launch = ray_cast_ms(args.size, args.spp)
    print(f"ray cast ({args.size}² x {args.spp} primary rays and as many shadow rays, Mitsuba's ray tracer alone): "
          f"{rays:.0f} ms; the render is {statistics.median(times) / rays:.1f}x that. Of the render: scene update "
          f"{update:.0f} ms, launch (rays, light sampling, film) {launch:.0f} ms")
    if not args.no_povray:
        from sasmi.scene.preset import load_preset

        wall, pov_cpu = povray_ms(load_preset(PRESET).sample(0, 0), args.size)
        print(f"POV-Ray on the first of those scenes ({args.size}x{args.size}, 32 emitters, 3x3 jittered + centre ray, "
              f"radiance only): {wall:.0f} ms wall, CPU {pov_cpu:.0f} ms; POV-Ray / Mitsuba: "
              f"{wall / statistics.median(times):.1f}x wall, {pov_cpu / statistics.median(cpu):.1f}x CPU")
    for workers in args.workers:
        ms = throughput_ms("render", workers, args.size, *args.chips)
        print(f"sasmi render --size {args.size} --workers {workers}: {ms:.0f} ms/chip "
              f"(chips {args.chips[0]}..{args.chips[1]}, start-up excluded)")
    for workers in args.workers if args.generate[1] > args.generate[0] else ():
        ms = throughput_ms("generate", workers, 128, *args.generate)
        print(f"sasmi generate --size 128 --workers {workers} (shipped generator, drawn floors): {1000 / ms:.1f} "
              f"chips/s (chips {args.generate[0]}..{args.generate[1]}, start-up excluded)")
    for count in args.rss_counts:
        rss, seconds = peak_rss_mb(count, args.rss_size)
        print(f"sasmi render --count {count} --size {args.rss_size}: peak RSS {rss:.0f} MB, "
              f"{seconds:.1f} s wall ({seconds / count * 1000:.0f} ms/image incl. start-up)")


if __name__ == "__main__":
    main()
