"""Peak memory of the evaluation at scale: N real + N generated random φ vectors (D = 1024)
and random images, through `sasmi.eval.evaluate.evaluate` (FID ± bootstrap, matched ratio, KID,
precision/recall, nearest neighbours in φ and pixels with their figures, t-SNE). Each N
runs in a fresh process, so each peak RSS is its own.

    .venv/bin/python benchmarks/evaluate.py [--sizes 6000 20000] [--bootstrap 2] [--image-size 32]

Memory does not depend on --bootstrap (only time does). Images are held as the evaluation holds
them, N × S² uint8 per set (read a block at a time: sasmi.eval.features.load_set).
Targets: < 2 GB at 6000 + 6000, < 4 GB at 20000 + 20000 (memory grows with N, not with N²).
"""
from __future__ import annotations

import argparse
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
    start = time.perf_counter()
    with tempfile.TemporaryDirectory() as out:
        report = evaluate(real, [fake], out, EvalConfig(bootstrap=bootstrap, kid_subsets=20))
    row = report.metrics["realism"]["fake"]
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"{n:>6} + {n:<6} {peak_mb:8.0f} MiB peak RSS ({inputs_mb:.0f} MiB of inputs)  "
          f"{time.perf_counter() - start:6.0f} s  FID {row['fid']:.1f}  precision {row['precision']:.3f}  "
          f"recall {row['recall']:.3f}", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[6000, 20000], help="N per set (default 6000 20000)")
    parser.add_argument("--bootstrap", type=int, default=2, help="FID resamples (time only; default 2)")
    parser.add_argument("--image-size", type=int, default=32, help="side of the random images (default 32)")
    parser.add_argument("--dim", type=int, default=1024, help="φ dimensions (default 1024)")
    parser.add_argument("--one", type=int, help=argparse.SUPPRESS)  # the child process: one size
    args = parser.parse_args()
    if args.one:
        one(args.one, args.bootstrap, args.image_size, args.dim)
        return
    print(f"evaluate(): random φ (D = {args.dim}) and {args.image_size}² px images, bootstrap {args.bootstrap}, "
          "one BLAS thread")
    for n in args.sizes:
        subprocess.run([sys.executable, __file__, "--one", str(n), "--bootstrap", str(args.bootstrap),
                        "--image-size", str(args.image_size), "--dim", str(args.dim)], check=True, cwd=REPO)


if __name__ == "__main__":
    main()
