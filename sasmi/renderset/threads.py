"""The cores' share of each of several busy processes.

Dr.Jit's (rendering) and torch's (networks) thread pools spin on every core by default; several
processes each doing so on a few cores run many times slower than one. Wherever processes
work at once (the processes of `render --workers` and `generate --workers`, Dask workers,
calibration trials), each sizes its pools to its share: cores // processes.
"""
from __future__ import annotations

import os


def local_threads(processes: int) -> int:
    """Threads per process when `processes` busy processes (or pools) share this machine's cores."""
    return max(1, (os.cpu_count() or 1) // processes)
