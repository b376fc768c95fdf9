"""Peak memory of a command and every process it starts (`--workers N` spawns N): the largest sum of their
resident sets, sampled every 0.2 s.

    .venv/bin/python benchmarks/peak_rss.py -- .venv/bin/sasmi generate cylinder_chip --count 300 --size 128 \\
        --workers 2 --out OUT
"""
from __future__ import annotations

import subprocess
import sys
import time

import psutil

INTERVAL_S = 0.2


def tree_rss(process: psutil.Process) -> int:
    total = 0
    for p in [process, *process.children(recursive=True)]:
        try:
            total += p.memory_info().rss
        except psutil.NoSuchProcess:  # ended between the listing and the reading
            pass
    return total


def main() -> None:
    command = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    if not command:
        sys.exit(__doc__)
    child = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    watched, peak = psutil.Process(child.pid), 0
    while child.poll() is None:
        try:
            peak = max(peak, tree_rss(watched))
        except psutil.NoSuchProcess:
            break
        time.sleep(INTERVAL_S)
    print(f"exit code {child.wait()}; peak RSS of the command and its processes: {peak / 2 ** 20:.0f} MiB")


if __name__ == "__main__":
    main()
