"""A render set made by local processes that each run the whole command on a share of its scenes.

`sasmi render --workers N` and `sasmi generate --workers N` start N processes, each making the
chips of one share (as --shard splits them) with cores // N threads for Dr.Jit and torch. Much of
a chip's time is single-threaded Python (drawing the scene, the floor's geometry, labels, masks,
files), which one process runs on one core whatever its thread pools do; whole processes use
every core for it (docs/scale.md). This process shows one progress bar over the folder and
waits; a share that fails stops the others (what they finished is kept, and rerunning the same
command resumes every share).
"""
from __future__ import annotations

import multiprocessing
import os
import signal
import sys
import time
from pathlib import Path
from typing import Callable

from tqdm import tqdm

from sasmi.errors import SasmiError, user_error_message

POLL_S = 0.5
STOP_S = 10.0  # a stopped share finishes the chip it is writing in this time, or is killed


def in_share(command: str, threads: int, body: Callable[[], None]) -> None:
    """Run body() as one share's process, Dr.Jit on `threads` threads: an error the user can fix ends it
    with the command's one line and exit code 2 (as `sasmi.cli.main` reports it), Ctrl-C (which reaches
    every process of the terminal) with 130; any other error with its traceback."""
    from sasmi.render.llvm import import_mitsuba

    try:
        import_mitsuba()[1].set_thread_count(threads)
        body()
    except KeyboardInterrupt:  # the first process reports it
        sys.exit(130)
    except Exception as e:
        message = user_error_message(e)
        if message is None:
            raise
        print(f"sasmi {command}: error: {message}", file=sys.stderr)
        sys.exit(2)


def complete_chips(out: Path, shard: tuple[int, int] = (0, 1)) -> int:
    """Chips of the shard (I, N) (index % N == I) with their labels file written (the last file of a chip:
    sasmi.renderset.write.write_one)."""
    folder, (i, n) = out / "labels", shard
    return sum(1 for p in folder.glob("[0-9]*.json") if int(p.stem) % n == i) if folder.is_dir() else 0


def run_shares(work: Callable[[int, int], None], shares: int, done: Callable[[], int], count: int, what: str,
               progress: bool = True) -> None:
    """Run work(share, shares) for share in 0..shares-1, each in a fresh process (spawned: nothing of
    this process's thread pools is inherited), showing done() of `count` chips; a SasmiError naming
    the first share that failed. `work` must be importable (a module-level function or a partial of one)."""
    context = multiprocessing.get_context("spawn")
    processes = [context.Process(target=work, args=(k, shares), name=f"{what} {k + 1}/{shares}", daemon=True)
                 for k in range(shares)]
    finished = done()
    try:
        for p in processes:
            p.start()
        with tqdm(total=count, initial=finished, unit="img", desc=what, disable=not progress,
                  dynamic_ncols=True) as bar:
            while not all(p.exitcode == 0 for p in processes):
                failed = next((p for p in processes if p.exitcode not in (None, 0)), None)
                if failed is not None:
                    raise SasmiError(f"{failed.name} stopped with exit code {failed.exitcode} (its error is "
                                     "above); finished chips are kept: rerun the same command to continue")
                time.sleep(POLL_S)
                now = done()
                bar.update(now - finished)
                finished = now
            bar.update(done() - finished)
    finally:
        # the others end as on Ctrl-C, cleanly (a killed process leaves its semaphores behind); then by force
        running = [p for p in processes if p.is_alive()]
        for p in running:
            os.kill(p.pid, signal.SIGINT)
        for p in running:
            p.join(STOP_S)
            if p.is_alive():
                p.kill()
                p.join()
