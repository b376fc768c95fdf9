"""Training across processes: `torchrun --nproc_per_node N -m sasmi train KIND ...`.

torchrun sets RANK, LOCAL_RANK and WORLD_SIZE; `start` joins the process group (gloo on
a CPU, nccl on CUDA, one GPU per process). The models are wrapped in
DistributedDataParallel, which averages their gradients over the processes.

--batch stays the global batch. Every process draws the global batch's random numbers
(data order, crops, flips, augmentation, GP interpolation, latent codes) from the same
seeded streams and keeps its own slice, so N processes train the same network as one
process at the same batch, up to the order of floating-point sums (tests/gan/test_distributed.py),
and a run resumes on any number of processes. Rank 0 alone writes the run folder.
"""
from __future__ import annotations

import gc
import os
from dataclasses import dataclass

import torch
import torch.distributed as dist

from sasmi.errors import SasmiError


@dataclass(frozen=True)
class World:
    rank: int = 0
    size: int = 1

    @property
    def main(self) -> bool:
        """The process that writes: checkpoints, logs, samples."""
        return self.rank == 0

    def local(self, batch: torch.Tensor) -> torch.Tensor:
        """This process's slice of a global batch (B, ...) → (B / size, ...)."""
        n = len(batch) // self.size
        return batch[self.rank * n:(self.rank + 1) * n]


_world = World()


def world() -> World:
    return _world


def start(device: torch.device) -> torch.device:
    """Join torchrun's process group when there is one; the device this process trains on."""
    global _world
    size = int(os.environ.get("WORLD_SIZE", "1"))
    if size == 1 or dist.is_initialized():
        return device
    if device.type == "cuda":
        device = torch.device("cuda", int(os.environ.get("LOCAL_RANK", "0")))
        torch.cuda.set_device(device)
    dist.init_process_group("nccl" if device.type == "cuda" else "gloo")
    _world = World(dist.get_rank(), dist.get_world_size())
    return device


def stop() -> None:
    global _world
    if dist.is_initialized():
        # A DDP wrapper left in a reference cycle would hold the gloo group until interpreter
        # exit, where its threads can die in a C++ destructor ("terminate called without an
        # active exception")
        gc.collect()
        dist.destroy_process_group()
    _world = World()


def check_batch(batch: int) -> None:
    if batch % _world.size:
        raise SasmiError(f"--batch {batch}: the global batch must divide evenly among the {_world.size} processes")


def parallel(module: torch.nn.Module) -> torch.nn.Module:
    """`module` with its gradients averaged over the processes (itself in a single process).
    Its state_dict stays the module's: checkpoints hold the unwrapped models."""
    if _world.size == 1:
        return module
    from torch.nn.parallel import DistributedDataParallel

    on_gpu = next(module.parameters()).device.type == "cuda"
    return DistributedDataParallel(module, device_ids=[torch.cuda.current_device()] if on_gpu else None)


def draw(rng: torch.Generator, n: int, *shape: int, normal: bool = False) -> torch.Tensor:
    """n samples of shape `shape` for this process: the global n·size are drawn, this slice kept."""
    return _world.local((torch.randn if normal else torch.rand)((n * _world.size, *shape), generator=rng))


def mean_logs(logs: dict[str, float]) -> dict[str, float]:
    """Every process logs (and picks best.pt by) the mean over the processes."""
    if _world.size == 1:
        return logs
    values = torch.tensor(list(logs.values()), dtype=torch.float64)
    dist.all_reduce(values)
    return dict(zip(logs, (values / _world.size).tolist()))


def barrier() -> None:
    if _world.size > 1:
        dist.barrier()
