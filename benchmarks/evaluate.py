"""Time of each stage and peak memory of the evaluation at scale: N real + N generated random φ
vectors (D = 1024) and random images, through `sasmi.eval.evaluate.evaluate` with its defaults
(realism: FID ±, matched ratio, KID, precision/recall; coverage; nearest neighbours in φ and pixels
with their figures; t-SNE; the two-sample test). Each N runs in a fresh process, so each peak RSS
is its own. φ itself is not computed (it is the encoder's time, linear in N).

    .venv/bin/python benchmarks/evaluate.py [--sizes 600 6000 20000] [--image-size 32 128] [--bootstrap 500]

Images are held as the evaluation holds them, N × S² uint8 per set (read a block at a time:
sasmi.eval.features.load_set). Targets: < 2 GB at 6000 + 6000, < 4 GB at 20000 + 20000.
"""
from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def one(n: int, bootstrap: int, image_size: int, dim: int) -> None:
    import numpy as np

    from sasmi.eval.config import EvalConfig
    from sasmi.eval.features import FeatureSet
    from sasmi.eval.evaluate import evaluate

    rng = np.random.default_rng(0)
    real = FeatureSet("real", Path("real"), rng.integers(0, 256, (n, image_size, image_size), np.uint8),
                      rng.standard_normal((n, dim)))
    fake = FeatureSet("fake", Path("fake"), rng.integers(0, 256, (n, image_size, image_size), np.uint8),
                      rng.standard_normal((n, dim)) + 0.02)
    inputs_mb = (real.phi.nbytes + fake.phi.nbytes + real.images.nbytes + fake.images.nbytes) / 2**20
    stages = []  # (stage, start time): each log line of the evaluation opens a stage

    def log(message: str) -> None:
        stages.append((message.split(":")[0].split(" (")[0], time.perf_counter()))

    start = time.perf_counter()
    with tempfile.TemporaryDirectory() as out:
        report = evaluate(real, [fake], out, EvalConfig(bootstrap=bootstrap), log)
    end = time.perf_counter()
    row = report.metrics["realism"]["fake"]
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    times = [(name, (stages[i + 1][1] if i + 1 < len(stages) else end) - t) for i, (name, t) in enumerate(stages)]
    print(f"{n:>6} + {n:<6} {image_size:>4} px {peak_mb:8.0f} MiB peak RSS ({inputs_mb:.0f} MiB of inputs)  "
          f"{end - start:6.1f} s: " + ", ".join(f"{name} {t:.1f} s" for name, t in times)
          + f"  (ratio {row['fid_ratio']:.3f}, recall {row['recall']:.3f})", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[600, 6000, 20000], help="N per set (default 600 6000 20000)")
    parser.add_argument("--bootstrap", type=int, default=500, help="at most this many replicates (default 500, as evaluate)")
    parser.add_argument("--image-size", type=int, nargs="+", default=[32, 128], help="sides of the random images (default 32 128)")
    parser.add_argument("--dim", type=int, default=1024, help="φ dimensions (default 1024)")
    parser.add_argument("--one", type=int, help=argparse.SUPPRESS)  # the child process: one size
    args = parser.parse_args()
    if args.one:
        one(args.one, args.bootstrap, args.image_size[0], args.dim)
        return
    print(f"evaluate(): random φ (D = {args.dim}), bootstrap {args.bootstrap}, {os.cpu_count()} cores")
    for image_size in args.image_size:
        for n in args.sizes:
            subprocess.run([sys.executable, __file__, "--one", str(n), "--bootstrap", str(args.bootstrap),
                            "--image-size", str(image_size), "--dim", str(args.dim)], check=True, cwd=REPO)


if __name__ == "__main__":
    main()
