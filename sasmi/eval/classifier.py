"""A chip classifier for yardsticks: the two-sample test (real or not?) and the ATR bench
(target or seafloor?). Two networks, one training loop, one scoring path.

- "small": four stride-2 convolutions and a linear unit, a fixed yardstick that trains in
  seconds on a CPU;
- "resnet18": He et al.'s ResNet-18 (BasicBlocks 2-2-2-2, 64-512 channels) from scratch, with a
  3x3 stride-1 stem for 64-128 px chips. Written here in torch: torchvision's build does not
  import beside the CPU wheel of torch that sasmi installs.

Images are (N, S, S) in [0, 1]; the networks see (B, 1, S, S) in [-1, 1] and return (B,) logits.
"""
from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from sasmi.errors import SasmiError
from sasmi.preprocess import unit_to_signed

NETS = ("small", "resnet18")


def small_cnn() -> nn.Module:
    def block(c_in: int, c_out: int) -> list[nn.Module]:
        return [nn.Conv2d(c_in, c_out, 3, stride=2, padding=1), nn.BatchNorm2d(c_out), nn.ReLU()]

    return nn.Sequential(*block(1, 16), *block(16, 32), *block(32, 64), *block(64, 64),
                         nn.AdaptiveAvgPool2d(1), nn.Flatten(), nn.Linear(64, 1), nn.Flatten(0))


class _Basic(nn.Module):
    """ResNet's BasicBlock: two 3x3 convolutions and a shortcut (1x1 where the shape changes)."""

    def __init__(self, c_in: int, c_out: int, stride: int):
        super().__init__()
        self.conv1 = nn.Conv2d(c_in, c_out, 3, stride, 1, bias=False)
        self.bn1 = nn.BatchNorm2d(c_out)
        self.conv2 = nn.Conv2d(c_out, c_out, 3, 1, 1, bias=False)
        self.bn2 = nn.BatchNorm2d(c_out)
        self.shortcut = nn.Identity() if stride == 1 and c_in == c_out else nn.Sequential(
            nn.Conv2d(c_in, c_out, 1, stride, bias=False), nn.BatchNorm2d(c_out))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = F.relu(self.bn1(self.conv1(x)))
        return F.relu(self.bn2(self.conv2(y)) + self.shortcut(x))


def resnet18() -> nn.Module:
    layers: list[nn.Module] = [nn.Conv2d(1, 64, 3, 1, 1, bias=False), nn.BatchNorm2d(64), nn.ReLU()]
    c_in = 64
    for c_out, stride in ((64, 1), (128, 2), (256, 2), (512, 2)):
        layers += [_Basic(c_in, c_out, stride), _Basic(c_out, c_out, 1)]
        c_in = c_out
    return nn.Sequential(*layers, nn.AdaptiveAvgPool2d(1), nn.Flatten(), nn.Linear(512, 1), nn.Flatten(0))


def make(net: str) -> nn.Module:
    if net not in NETS:
        raise SasmiError(f"--net {net}: choose one of {', '.join(NETS)}")
    return small_cnn() if net == "small" else resnet18()


def augment(x: torch.Tensor, gen: torch.Generator) -> torch.Tensor:
    """Up-down flips and small shifts only: a left-right flip would put shadows on the sonar's side."""
    flip = torch.rand(x.shape[0], generator=gen) < 0.5
    x = torch.where(flip[:, None, None, None], x.flip(-2), x)
    dy, dx = (int(v) for v in torch.randint(-4, 5, (2,), generator=gen))
    return torch.roll(x, shifts=(dy, dx), dims=(-2, -1))


def train(positives: np.ndarray, negatives: np.ndarray, steps: int, seed: int, net: str = "small",
          batch: int = 32, lr: float = 1e-3, model: nn.Module | None = None, device="cpu",
          replay: tuple[np.ndarray, np.ndarray] | None = None) -> nn.Module:
    """Balanced batches (half each class, whatever the pool sizes) from two (N, S, S) pools in [0, 1].

    `model` continues training a network (fine-tuning after pretraining) instead of a new one.
    `replay` (positives, negatives) fills half of each class's share of every batch, so that
    fine-tuning on a few chips does not pull the network away from the many it was pretrained on.
    """
    if len(positives) == 0 or len(negatives) == 0 or (replay is not None and min(map(len, replay)) == 0):
        raise SasmiError("a classifier needs chips of both classes")
    gen = torch.Generator().manual_seed(seed)
    if model is None:
        torch.manual_seed(seed)
        model = make(net)
    # channels-last convolutions and a fused Adam step: the small CNN's batch in 16 ms on 2 AVX2 cores, not 27,
    # with the same two-sample AUCs to three decimals
    model = model.to(device, memory_format=torch.channels_last)
    opt = torch.optim.Adam(model.parameters(), lr=lr, fused=True)
    half = batch // 2
    # per class (negatives, then targets): the pools its half of a batch is drawn from, and how many from each
    shares = [[(torch.from_numpy(negatives), half)], [(torch.from_numpy(positives), half)]]
    if replay is not None:
        for share, again in zip(shares, (replay[1], replay[0])):
            share[:] = [(share[0][0], half - half // 2), (torch.from_numpy(again), half // 2)]
    y = torch.cat([torch.zeros(half), torch.ones(half)]).to(device)
    model.train()
    for _ in range(steps):
        picks = [pool[torch.randint(len(pool), (k,), generator=gen)] for share in shares for pool, k in share]
        x = augment(unit_to_signed(torch.cat(picks)[:, None].float()), gen)  # (B, 1, S, S) in [-1, 1]
        x = x.to(device, memory_format=torch.channels_last)
        loss = F.binary_cross_entropy_with_logits(model(x), y)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
    return model.eval()


@torch.no_grad()
def predict(model: nn.Module, images: np.ndarray, batch: int = 64) -> np.ndarray:
    """(N,) probabilities of the positive class for (N, S, S) images in [0, 1], on the model's device."""
    device = next(model.parameters(), torch.zeros(())).device  # a model without weights: the CPU
    x = unit_to_signed(torch.from_numpy(images)[:, None].float())
    return torch.sigmoid(torch.cat([model(x[i:i + batch].to(device, memory_format=torch.channels_last))
                                    for i in range(0, len(x), batch)])).cpu().numpy()
