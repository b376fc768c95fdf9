"""Training across processes: SAS GAN steps/s of `torchrun --nproc_per_node N -m sasmi train sasgan`
at one global batch, for each N (gloo on a CPU, nccl on CUDA: --device).

    .venv/bin/python benchmarks/ddp.py [--procs 1 2] [--batch 8] [--size 128] [--steps 12] [--device cpu]

Each process gets cores / N torch threads. A rate is (steps of a long run - steps of a 2-step
run) over the difference of their wall times, so start-up (torchrun, reading data, joining the
process group) is excluded. Data: random images in a temporary folder, φ a 2-step autoencoder.
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]


def sasmi(procs: int, argv: list[str], cwd: Path, threads: int) -> float:
    env = os.environ | {"OMP_NUM_THREADS": str(threads), "OMP_WAIT_POLICY": "PASSIVE", "PYTHONPATH": str(REPO)}
    launcher = ["-m", "torch.distributed.run", "--standalone", "--nproc_per_node", str(procs)] if procs > 1 else []
    start = time.perf_counter()
    subprocess.run([sys.executable, *launcher, "-m", "sasmi", *argv], cwd=cwd, env=env, check=True,
                   capture_output=True, text=True)
    return time.perf_counter() - start


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--procs", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--batch", type=int, default=8, help="the global batch (default 8)")
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--steps", type=int, default=12, help="steps of the long run (default 12)")
    ap.add_argument("--device", default="cpu")
    args = ap.parse_args()
    from sasmi.images import write_gray

    cores = os.cpu_count() or 1
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        rng = np.random.default_rng(0)
        for folder in ("real", "renders/images"):
            for i in range(64):
                write_gray(root / folder / f"{i}.png", rng.random((args.size, args.size)))
        common = ["--size", str(args.size), "--device", args.device]
        sasmi(1, ["train", "autoencoder", "--real", "real", "--out", "phi", "--steps", "2", *common], root, cores)
        print(f"SAS GAN (small nets) at {args.size}², global batch {args.batch}, {args.device}, {cores} cores")
        for procs in args.procs:
            threads = max(1, cores // procs)
            seconds = {}
            for steps in (2, args.steps):
                seconds[steps] = sasmi(procs, ["train", "sasgan", "--real", "real", "--renders", "renders", "--phi",
                                               "phi", "--out", f"gan_{procs}_{steps}", "--steps", str(steps),
                                               "--batch", str(args.batch), *common], root, threads)
            rate = (args.steps - 2) / (seconds[args.steps] - seconds[2])
            print(f"  {procs} process(es) × {threads} thread(s): {rate:.2f} steps/s "
                  f"({rate * args.batch:.1f} images/s through the generator)", flush=True)


if __name__ == "__main__":
    main()
