"""The shipped generator's translation of 128 px chips, ms per chip, with its up stages computed at the low
resolution (as `load_generator` folds them: sasmi.gan.upsample) and as the plain [nearest ×2 → 3×3 conv]
layers, in turn (a machine's speed drifts between runs); and the largest difference between their outputs.

    .venv/bin/python benchmarks/translate_speed.py [--batches 10] [--rounds 3]
"""
from __future__ import annotations

import argparse
import copy
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import torch
import torch.nn as nn

from sasmi.gan.generator import load_generator
from sasmi.gan.translate import translate
from sasmi.gan.upsample import NearestUpConv
from sasmi.weights import shipped

sys.path.insert(0, str(Path(__file__).resolve().parent))
from render import cpu_description  # noqa: E402


def unfolded(generator: nn.Module) -> nn.Module:
    """A copy whose up stages are the plain upsampling and conv layers again."""
    plain = copy.deepcopy(generator)
    for i, layer in enumerate(plain.net):
        if isinstance(layer, NearestUpConv):
            plain.net[i - 1], plain.net[i] = layer.unfolded()
    return plain


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--batches", type=int, default=10, help="batches of 16 chips a round")
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()
    folded = load_generator(shipped("sasgan"))
    nets = {"folded": folded, "plain": unfolded(folded)}
    chips = np.random.default_rng(0).random((16, 128, 128), dtype=np.float32)
    outputs = {name: translate(net, chips) for name, net in nets.items()}  # warm-up
    times: dict[str, list[float]] = {name: [] for name in nets}
    for _ in range(args.rounds):
        for name, net in nets.items():
            start = time.perf_counter()
            for _ in range(args.batches):
                translate(net, chips)
            times[name].append((time.perf_counter() - start) / (16 * args.batches) * 1000)
    print(f"machine: {cpu_description()}; torch {torch.__version__} on {torch.get_num_threads()} threads")
    for name, values in times.items():
        print(f"{name}: {statistics.median(values):.2f} ms/chip (rounds: {', '.join(f'{v:.2f}' for v in values)})")
    print(f"folded / plain: {statistics.median(times['folded']) / statistics.median(times['plain']):.2f}; "
          f"largest output difference {np.abs(outputs['folded'] - outputs['plain']).max():.1e} (outputs in [0, 1])")


if __name__ == "__main__":
    main()
