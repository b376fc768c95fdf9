"""`sasmi atr-bench`: does synthetic data help a target-vs-seafloor classifier on real chips?

One small fixed CNN, one fixed training budget, several seeds, three training sets:
- real:            the real training chips (targets/ and seafloor/);
- real+synthetic:  those plus the synthetic target chips (and synthetic seafloor, if given);
- synthetic:       the synthetic target chips with real seafloor only.
Each is scored on the real test chips by accuracy (threshold 0.5) and ROC AUC. With
`real_per_class`, each seed draws that many real chips per class, the few-real-chips case
that synthetic data is meant to help.
"""
from __future__ import annotations

import json
import os
import sys
import warnings
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from sasmi.errors import SasmiError
from sasmi.images import list_images, write_text
from sasmi.preprocess import check_size, load_image, unit_to_signed

REGIMES = ("real", "real+synthetic", "synthetic")


@dataclass(frozen=True)
class AtrConfig:
    size: int = 128  # chips are brought to size x size by the one preprocessing path
    seeds: int = 5  # independent trainings per regime: the spread is what makes a difference credible
    steps: int = 300  # fixed budget: every regime sees the same number of batches
    batch: int = 32  # half targets, half seafloor, whatever the pool sizes
    lr: float = 1e-3
    real_per_class: tuple[int | None, ...] = (None,)  # None = every real training chip


def classifier() -> torch.nn.Module:
    """(B, 1, S, S) in [-1, 1] -> (B,) logits of 'target'. Small on purpose: a fixed yardstick, not a model."""
    def block(c_in: int, c_out: int) -> list[torch.nn.Module]:
        return [torch.nn.Conv2d(c_in, c_out, 3, stride=2, padding=1), torch.nn.BatchNorm2d(c_out), torch.nn.ReLU()]

    return torch.nn.Sequential(*block(1, 16), *block(16, 32), *block(32, 64), *block(64, 64),
                               torch.nn.AdaptiveAvgPool2d(1), torch.nn.Flatten(), torch.nn.Linear(64, 1),
                               torch.nn.Flatten(0))


def load_folder(folder: Path, size: int, what: str) -> np.ndarray:
    """(N, S, S) in [0, 1]; unreadable files are skipped with one warning each."""
    if not folder.is_dir():
        raise SasmiError(f"{what} {folder}: not a folder")
    images = []
    for path in list_images(folder):
        try:
            images.append(load_image(path, size))
        except SasmiError as e:
            warnings.warn(f"skipping {e}", stacklevel=2)
    if not images:
        raise SasmiError(f"{what} {folder}: no readable image in it")
    return np.stack(images)


def _synthetic_folders(folder: Path) -> tuple[Path, Path | None]:
    targets = folder / "targets" if (folder / "targets").is_dir() else folder
    seafloor = folder / "seafloor" if (folder / "seafloor").is_dir() else None
    return targets, seafloor


def _augment(x: torch.Tensor, gen: torch.Generator) -> torch.Tensor:
    # up-down flips and small shifts only: a left-right flip would put shadows on the wrong side
    flip = torch.rand(x.shape[0], generator=gen) < 0.5
    x = torch.where(flip[:, None, None, None], x.flip(-2), x)
    dy, dx = (int(v) for v in torch.randint(-4, 5, (2,), generator=gen))
    return torch.roll(x, shifts=(dy, dx), dims=(-2, -1))


def train_classifier(targets: np.ndarray, seafloor: np.ndarray, cfg: AtrConfig, seed: int) -> torch.nn.Module:
    """Balanced batches from two pools of (N, S, S) images in [0, 1]."""
    gen = torch.Generator().manual_seed(seed)
    torch.manual_seed(seed)
    model = classifier()
    opt = torch.optim.Adam(model.parameters(), lr=cfg.lr)
    pools = [torch.from_numpy(seafloor), torch.from_numpy(targets)]
    half = cfg.batch // 2
    model.train()
    for _ in range(cfg.steps):
        picks = [pool[torch.randint(len(pool), (half,), generator=gen)] for pool in pools]
        x = _augment(unit_to_signed(torch.cat(picks)[:, None]), gen)  # (B, 1, S, S) in [-1, 1]
        y = torch.cat([torch.zeros(half), torch.ones(half)])
        loss = F.binary_cross_entropy_with_logits(model(x), y)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
    return model.eval()


@torch.no_grad()
def score(model: torch.nn.Module, targets: np.ndarray, seafloor: np.ndarray) -> dict:
    from sklearn.metrics import roc_auc_score

    x = unit_to_signed(torch.from_numpy(np.concatenate([targets, seafloor]))[:, None])
    p = torch.sigmoid(torch.cat([model(x[i:i + 64]) for i in range(0, len(x), 64)])).numpy()
    y = np.concatenate([np.ones(len(targets)), np.zeros(len(seafloor))])
    return {"accuracy": float(((p > 0.5) == y).mean()), "auc": float(roc_auc_score(y, p))}


def _draw(pool: np.ndarray, n: int | None, rng: np.random.Generator) -> np.ndarray:
    return pool if n is None or n >= len(pool) else pool[rng.choice(len(pool), n, replace=False)]


def _mean_std(values: list[float]) -> dict:
    return {"mean": float(np.mean(values)), "std": float(np.std(values)), "values": values}


def atr_bench(real_train: str | os.PathLike, real_test: str | os.PathLike, synthetic: str | os.PathLike,
              out: str | os.PathLike, cfg: AtrConfig = AtrConfig()) -> dict:
    check_size(cfg.size)
    real_train, real_test, synthetic, out = Path(real_train), Path(real_test), Path(synthetic), Path(out)
    pools = {"train_targets": load_folder(real_train / "targets", cfg.size, "--real-train"),
             "train_seafloor": load_folder(real_train / "seafloor", cfg.size, "--real-train"),
             "test_targets": load_folder(real_test / "targets", cfg.size, "--real-test"),
             "test_seafloor": load_folder(real_test / "seafloor", cfg.size, "--real-test")}
    syn_targets, syn_seafloor = _synthetic_folders(synthetic)
    pools["syn_targets"] = load_folder(syn_targets, cfg.size, "--synthetic")
    pools["syn_seafloor"] = load_folder(syn_seafloor, cfg.size, "--synthetic") if syn_seafloor else pools["syn_targets"][:0]

    results: dict = {}
    for n in cfg.real_per_class:
        key = "all" if n is None else str(n)
        results[key] = {}
        for regime in REGIMES:
            runs = []
            for seed in range(cfg.seeds):
                rng = np.random.default_rng(seed)
                real_t, real_s = _draw(pools["train_targets"], n, rng), _draw(pools["train_seafloor"], n, rng)
                if regime == "real":
                    t, s = real_t, real_s
                elif regime == "real+synthetic":
                    t, s = np.concatenate([real_t, pools["syn_targets"]]), np.concatenate([real_s, pools["syn_seafloor"]])
                else:
                    t, s = pools["syn_targets"], np.concatenate([real_s, pools["syn_seafloor"]])
                model = train_classifier(t, s, cfg, seed)
                runs.append(score(model, pools["test_targets"], pools["test_seafloor"]))
                print(f"atr-bench: real per class {key}, {regime}, seed {seed}: accuracy {runs[-1]['accuracy']:.3f} "
                      f"AUC {runs[-1]['auc']:.3f}", file=sys.stderr, flush=True)
            results[key][regime] = {m: _mean_std([r[m] for r in runs]) for m in ("accuracy", "auc")}

    metrics = {"config": {**asdict(cfg), "real_per_class": [n for n in cfg.real_per_class]},
               "inputs": {"real_train": str(real_train), "real_test": str(real_test), "synthetic": str(synthetic)},
               "counts": {k: len(v) for k, v in pools.items()}, "results": results}
    write_text(out / "metrics.json", json.dumps(metrics, indent=2) + "\n")
    write_text(out / "table.md", table_markdown(results))
    plot(results, out / "atr_bench.png")
    return metrics


def table_markdown(results: dict) -> str:
    lines = ["| real chips per class | trained on | accuracy | ROC AUC |", "|---|---|---:|---:|"]
    for key, regimes in results.items():
        for regime, m in regimes.items():
            lines.append(f"| {key} | {regime} | {m['accuracy']['mean']:.3f} ± {m['accuracy']['std']:.3f} "
                         f"| {m['auc']['mean']:.3f} ± {m['auc']['std']:.3f} |")
    return "\n".join(lines) + "\n"


def plot(results: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from sasmi.images import atomic_path

    keys = list(results)
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.2), sharey=False)
    width = 0.8 / len(REGIMES)
    for ax, metric in zip(axes, ("accuracy", "auc")):
        for j, regime in enumerate(REGIMES):
            means = [results[k][regime][metric]["mean"] for k in keys]
            stds = [results[k][regime][metric]["std"] for k in keys]
            ax.bar(np.arange(len(keys)) + j * width, means, width, yerr=stds, capsize=3, label=regime)
        ax.set_xticks(np.arange(len(keys)) + width * (len(REGIMES) - 1) / 2, keys)
        ax.set_xlabel("real chips per class")
        ax.set_title("accuracy" if metric == "accuracy" else "ROC AUC")
        ax.set_ylim(0.4 if metric == "auc" else 0.0, 1.0)
    axes[0].legend(fontsize=8, loc="lower right")
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=100)
    plt.close(fig)
