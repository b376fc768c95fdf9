"""What several commands share: the device flag, trained-run flags, torch threads."""
from __future__ import annotations

import argparse
import os

from sasmi.errors import SasmiError


def add_device(p: argparse.ArgumentParser) -> None:
    p.add_argument("--device", default="auto", help="auto (CUDA when present), cpu, cuda or cuda:N")


def add_threads(p: argparse.ArgumentParser) -> None:
    p.add_argument("--threads", type=int, metavar="N",
                   help="torch CPU threads (default: torch's choice; 1 when other jobs share the CPU)")


def add_generator(p: argparse.ArgumentParser, shipped: bool = False) -> None:
    p.add_argument("--generator", required=not shipped, metavar="RUN",
                   help="a `sasmi train sasgan` run folder, or a weights file"
                        + (" (default: the shipped reference generator, docs/models.md)" if shipped else ""))
    p.add_argument("--checkpoint", default="last", metavar="last|best|PATH",
                   help="last: the end of training; best: the step with the lowest averaged score "
                        "(docs/gan.md); or a checkpoint file")


def resolve_device(name: str):
    """The torch.device of a --device flag, or a SasmiError."""
    import torch

    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    try:
        device = torch.device(name)
    except RuntimeError:
        raise SasmiError(f"--device {name!r}: expected auto, cpu, cuda or cuda:N") from None
    if device.type not in ("cpu", "cuda"):
        raise SasmiError(f"--device {name!r}: expected auto, cpu, cuda or cuda:N")
    if device.type == "cuda" and not torch.cuda.is_available():
        raise SasmiError(f"--device {name}: CUDA is not available on this machine")
    return device


def apply_threads(threads: int | None) -> None:
    """Call before anything imports torch. Idle OpenMP threads then sleep instead of
    spinning: on a CPU that other jobs share, spinning threads multiply the CPU time of a
    SAS GAN step (docs/gan.md, *GPU and CPU notes*).
    OMP_WAIT_POLICY=ACTIVE in the environment restores spinning."""
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    if threads is None:
        return
    if not 1 <= threads <= (os.cpu_count() or 1) * 4:
        raise SasmiError(f"--threads {threads}: must be in [1, {(os.cpu_count() or 1) * 4}]")
    import torch

    torch.set_num_threads(threads)


def check_batch(batch: int) -> int:
    if not 1 <= batch <= 1024:
        raise SasmiError(f"--batch {batch}: must be an integer in [1, 1024]")
    return batch


def add_translation_flags(p: argparse.ArgumentParser, shipped: bool = False) -> None:
    """What every command that runs a generator takes: which one (`shipped`: the shipped one by default),
    batch, device, threads."""
    add_generator(p, shipped)
    p.add_argument("--batch", type=int, default=16, help="images per generator pass")
    add_device(p)
    add_threads(p)


def generator_from(args: argparse.Namespace):
    """The generator the translation flags name, in eval mode on its device (torch is imported here)."""
    apply_threads(args.threads)  # before torch is imported
    check_batch(args.batch)
    from sasmi.gan.generator import load_generator
    from sasmi.weights import shipped

    return load_generator(args.generator or shipped("sasgan"), resolve_device(args.device), args.checkpoint)
