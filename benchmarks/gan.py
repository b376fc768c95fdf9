"""GAN speed: generator inference ms/image at 256² (batch 1 and 16) and training steps/s.

    .venv/bin/python benchmarks/gan.py                       # CPU, and CUDA when present
    .venv/bin/python benchmarks/gan.py --nets small paper --train-size 128 --train-steps 20
    .venv/bin/python benchmarks/gan.py --devices cuda --kinds sasgan --recipe small_data --precision bf16 fp32

Training steps/s come from the real training loop on a temporary folder of random
images, timed as the difference between an N+2-step and a 2-step run, so start-up
(reading data, TensorBoard) is excluded. Beside the wall-clock rate it prints the CPU
seconds per step (all threads): on a machine that other jobs share, the wall clock
measures the load, while CPU time at 1 thread (--threads 1) measures the work; one SAS GAN or DCGAN step is n_critic = 5
critic updates and one generator update (`--recipe small_data`: the recipe `sasmi fit` trains, 2 critic
updates). On CUDA each training is timed under bf16 autocast and in float32 (`--precision`;
a CPU always trains in float32). The paper net at 256² on a CPU takes
minutes; it runs on CUDA by default and on the CPU only when asked for.
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

# run as a script, this file's folder comes first on sys.path and its name would shadow the gan package
sys.path = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).resolve().parent]

# as the sasmi commands do (sasmi/cli/common.py): idle OpenMP threads sleep, not spin;
# OMP_WAIT_POLICY=ACTIVE in the environment measures the spinning default
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numpy as np  # noqa: E402
import torch  # noqa: E402

from sasmi.gan.critic import CRITIC_NETS  # noqa: E402
from sasmi.gan.dcgan import DCGAN_NETS  # noqa: E402
from sasmi.gan.generator import GENERATOR_NETS, Generator  # noqa: E402
from sasmi.gan.kinds.autoencoder import AUTOENCODER  # noqa: E402
from sasmi.gan.kinds.dcgan import DCGAN  # noqa: E402
from sasmi.gan.kinds.sasgan import SASGAN  # noqa: E402
from sasmi.gan.loop import train  # noqa: E402
from sasmi.images import write_gray  # noqa: E402
from sasmi.masks import write_class_mask  # noqa: E402
from sasmi.gan.recipes import load_recipe  # noqa: E402


def sync(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize(device)


@torch.no_grad()
def inference_ms(net: str, device: torch.device, batch: int, size: int = 256, repeats: int = 3) -> float:
    generator = Generator(GENERATOR_NETS[net]).to(device).eval()
    x = torch.rand(batch, 1, size, size, device=device) * 2 - 1
    generator(x)  # warm-up (allocations, cuDNN autotuning)
    sync(device)
    start = time.perf_counter()
    for _ in range(repeats):
        generator(x)
    sync(device)
    return (time.perf_counter() - start) / repeats / batch * 1000


def training_steps_per_s(kind, net: str, device: torch.device, size: int, steps: int,
                         data: Path, settings: dict, bf16: bool) -> tuple[float, float]:
    """(steps/s by the wall clock, CPU seconds per step over all threads)."""
    inputs = {"real": data / "real"}
    if kind is SASGAN:
        inputs |= {"renders": data / "renders", "phi": data / f"ae{size}"}

    def run(n: int) -> tuple[float, float]:
        cfg = replace(kind.config(), steps=n, size=size, sample_every=10 ** 7, checkpoint_every=10 ** 7, amp=bf16)
        if kind is SASGAN:
            size_of = GENERATOR_NETS[net]  # the recipe's generator options at this net's width and depth
            generator = replace(settings.get("generator", cfg.generator), width=size_of.width, blocks=size_of.blocks)
            cfg = replace(cfg, **{**settings, "generator": generator, "critic": CRITIC_NETS[net]})
        if kind is DCGAN:
            cfg = replace(cfg, dcgan=DCGAN_NETS[net], critic=CRITIC_NETS[net], final_samples=1)
        out = Path(tempfile.mkdtemp(dir=data))
        wall, cpu = time.perf_counter(), time.process_time()
        train(kind, cfg, out, inputs, device)
        sync(device)
        return time.perf_counter() - wall, time.process_time() - cpu

    (wall_n, cpu_n), (wall_2, cpu_2) = run(steps + 2), run(2)
    return steps / (wall_n - wall_2), (cpu_n - cpu_2) / steps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--devices", nargs="+", help="default: cpu, and cuda when present")
    parser.add_argument("--nets", nargs="+", choices=sorted(GENERATOR_NETS),
                        help="network sizes (default: small on CPU, small and paper on CUDA)")
    parser.add_argument("--train-size", type=int, default=128, help="training image size (default 128, the chips)")
    parser.add_argument("--train-steps", type=int, default=10, help="timed training steps per kind (default 10)")
    parser.add_argument("--kinds", nargs="+", choices=("autoencoder", "sasgan", "dcgan"),
                        default=["autoencoder", "sasgan", "dcgan"], help="run kinds to time (default all)")
    parser.add_argument("--threads", type=int, help="torch CPU threads (default torch's choice)")
    parser.add_argument("--recipe", metavar="NAME|FILE", help="SAS GAN settings of a recipe (as `sasmi fit --recipe`; "
                                                        "default: the SasganRun defaults)")
    parser.add_argument("--precision", nargs="+", choices=("bf16", "fp32"), default=["bf16", "fp32"],
                        help="CUDA training precisions to time (default both; a CPU trains in float32)")
    parser.add_argument("--no-inference", action="store_true", help="time training only")
    args = parser.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    devices = args.devices or ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])
    settings = load_recipe(args.recipe) if args.recipe else {}

    with tempfile.TemporaryDirectory() as tmp:
        data = Path(tmp)
        rng = np.random.default_rng(0)
        for i in range(16):
            write_gray(data / "real" / f"{i}.png", rng.random((args.train_size, args.train_size)))
            write_gray(data / "renders" / "images" / f"{i}.png", rng.random((args.train_size, args.train_size)))
            mask = np.zeros((args.train_size, args.train_size), np.uint8)  # a target and its shadow, for the mask term
            mask[40:56, 40:56], mask[40:56, 56:96] = 1, 2
            write_class_mask(data / "renders" / "masks" / f"{i}.png", mask)
        ae_cfg = replace(AUTOENCODER.config(), steps=1, size=args.train_size)
        train(AUTOENCODER, ae_cfg, data / f"ae{args.train_size}", {"real": data / "real"}, torch.device("cpu"))

        print(f"torch {torch.__version__}, {torch.get_num_threads()} CPU threads")
        for name in devices:
            device = torch.device(name)
            label = torch.cuda.get_device_name(device) if device.type == "cuda" else "CPU"
            for net in args.nets or (["small"] if device.type == "cpu" else ["small", "paper"]):
                for batch in () if args.no_inference else (1, 16):
                    ms = inference_ms(net, device, batch)
                    print(f"{label:>12}  generator {net:<5} 256² batch {batch:>2}: {ms:8.2f} ms/image")
                for kind in (AUTOENCODER, SASGAN, DCGAN)[net != "small":]:  # the autoencoder has one size
                    if kind.name not in args.kinds:
                        continue
                    for precision in args.precision if device.type == "cuda" else ["fp32"]:
                        rate, cpu = training_steps_per_s(kind, net, device, args.train_size, args.train_steps,
                                                         data, settings, precision == "bf16")
                        print(f"{label:>12}  train {kind.name:<11} {net:<5} {args.train_size}² batch "
                              f"{kind.config().batch} {precision}: {rate:6.2f} steps/s, {cpu:6.2f} CPU s/step "
                              f"(load {os.getloadavg()[0]:.1f})")


if __name__ == "__main__":
    main()
