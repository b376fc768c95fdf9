"""Render work on Dask: an existing cluster (`--scheduler tcp://HOST:PORT`) or a local one (`--workers N`).

The driver claims each item (a chip index, a tar shard) just before it submits it and keeps
only a few tasks per worker thread in flight, so several drivers on one folder share the
work instead of one claiming everything up front. Workers write their chips themselves
(the output folder must be on a filesystem they share) or return them to the driver.

Thread pools (sasmi.renderset.threads): a local cluster of N workers gives each cores // N Dr.Jit
threads (the caller counts a generator in the driver as one more); a worker of a remote
cluster takes as many as Dask gave it (its --nthreads, e.g. cores / processes of a
dask-jobqueue job).
"""
from __future__ import annotations

import contextlib
import logging
from typing import Callable, Iterator

from sasmi.errors import SasmiError

CONNECT_TIMEOUT_S = 30
TASKS_PER_THREAD = 2  # in flight per worker thread: enough to hide the round trip, few enough to share


@contextlib.contextmanager
def dask_client(scheduler: str | None, workers: int) -> Iterator:
    """A distributed.Client of the cluster at `scheduler`, or of a new local cluster of `workers` processes
    with one thread each (closed on exit)."""
    from distributed import Client, LocalCluster

    if scheduler:
        try:
            client = Client(scheduler, timeout=CONNECT_TIMEOUT_S)
        except (OSError, TimeoutError, ValueError) as e:
            raise SasmiError(f"--scheduler {scheduler}: cannot connect within {CONNECT_TIMEOUT_S} s "
                             f"({type(e).__name__}: {e}); allowed: the address of a running dask scheduler, "
                             "tcp://HOST:PORT") from None
        with client:
            yield client
        return
    with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None,
                      silence_logs=logging.ERROR) as cluster, Client(cluster) as client:
        yield client


def _on_worker(task: Callable, job, item, threads: int | None, kwargs: dict):
    """Runs on a Dask worker: no thread count given means the worker's own (its --nthreads)."""
    if threads is None:
        from distributed import get_worker

        threads = get_worker().state.nthreads
    return task(job, item, threads=threads, **kwargs)


def stream(client, task: Callable, job, items: list, claim: Callable[[object], bool], threads: int | None,
           **kwargs) -> Iterator[tuple[object, object]]:
    """(item, task(job, item, threads=threads, **kwargs)) for each item that `claim` grants, as tasks finish.

    An error in a task cancels the rest and is raised here (claims are the caller's to release)."""
    from distributed import as_completed

    job_future = client.scatter(job, broadcast=True, hash=False)
    pending = iter(items)
    running = as_completed(loop=client.loop)
    item_of: dict = {}

    def window() -> int:
        return TASKS_PER_THREAD * max(1, sum(client.nthreads().values()))

    def top_up(limit: int) -> None:
        while running.count() < limit:
            item = next((i for i in pending if claim(i)), None)
            if item is None:
                return
            future = client.submit(_on_worker, task, job_future, item, threads, kwargs, pure=False)
            item_of[future.key] = item
            running.add(future)

    limit = window()
    top_up(limit)
    try:
        for done, future in enumerate(running, 1):
            yield item_of.pop(future.key), future.result()
            if done % 32 == 0:  # a cluster may grow (dask-jobqueue jobs start late)
                limit = window()
            top_up(limit)
    finally:
        left = list(running.futures)
        if left:
            client.cancel(left)
