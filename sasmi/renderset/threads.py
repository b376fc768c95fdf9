"""Thread pools that share the cores: Dr.Jit's (rendering) and torch's (networks).

Each pool spins on every core by default; two of them at once on a few cores make a
training step beside a Mitsuba render many times slower. Wherever both run at
the same time — a render worker beside a generator in the driver (`generate --workers`),
a renderer inside a fitting loop — each gets its share: cores // processes.
"""
from __future__ import annotations

import os
import sys


def local_threads(processes: int) -> int:
    """Threads per process when `processes` busy processes (or pools) share this machine's cores."""
    return max(1, (os.cpu_count() or 1) // processes)


def share_torch_threads(processes: int) -> None:
    """torch in this process takes its share of the cores (never more than it had; e.g. --threads)."""
    if "torch" in sys.modules:
        import torch

        torch.set_num_threads(min(torch.get_num_threads(), local_threads(processes)))


def size_thread_pools(pools: int = 2) -> int:
    """Dr.Jit's and torch's pools in this process, running at once, each get cores // pools threads
    (the pools already imported; a later import keeps its default). Returns that count."""
    threads = local_threads(pools)
    if "drjit" in sys.modules:
        import drjit

        drjit.set_thread_count(threads)
    share_torch_threads(pools)
    return threads
