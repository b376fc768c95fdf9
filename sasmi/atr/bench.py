"""`sasmi atr-bench`: does synthetic data make a target-vs-seafloor classifier better on real chips?

For each number of real chips per class and each seed, one draw of real training chips is shared
by every way of using the synthetic chips, so that ways are compared pair by pair:
- real:      the drawn real targets and negatives alone (the baseline);
- mixed:     those plus the synthetic targets (and synthetic negatives, when given);
- alone:     the synthetic targets with the drawn real negatives (and synthetic negatives);
- pretrain:  trained on synthetic targets and negatives first, then fine-tuned on the real draw;
- replay:    pretrained so, then fine-tuned on the real draw with the synthetic chips replayed
             beside it (half of each class's share of a batch real, half synthetic).
At 0 real chips per class no real target is used: `alone` trains on the synthetic targets and every
real negative, and is paired with `real` at 40 per class (or the nearest count run).
Each network is scored on real test chips of scene groups never trained on: accuracy, ROC AUC and
the probability of detection at a false-alarm rate of `pfa`. Every run is kept in RUN/runs.jsonl,
so a rerun of the same command continues where it stopped.
"""
from __future__ import annotations

import json
import sys
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from sasmi.atr.pools import Pool, load_pool, same_sonar, split_folders, target_sonars
from sasmi.atr.summary import paired, plot, summarise, table_markdown
from sasmi.errors import SasmiError
from sasmi.eval import classifier
from sasmi.images import FolderLock, write_text
from sasmi.preprocess import check_size

WAYS = ("real", "mixed", "alone", "pretrain", "replay")
YARDSTICK = 40  # real chips per class that the no-real-target arm is paired with


@dataclass(frozen=True)
class AtrConfig:
    size: int = 64  # chips are brought to size x size by the one preprocessing path
    seeds: int = 10  # real draws and trainings per arm; every arm uses the same draws
    steps: int = 200  # training batches per network (and again for fine-tuning): a fixed budget
    batch: int = 32  # half targets, half negatives, whatever the pool sizes
    lr: float = 1e-3
    net: str = "small"  # sasmi.eval.classifier: "small" (a fixed yardstick) or "resnet18" (from scratch)
    real_per_class: tuple[int | None, ...] = (0, 10, 40, None)  # None: every real training chip
    ways: tuple[str, ...] = WAYS
    same_sonar: bool = True  # real negatives only of the real targets' sonar (sasmi.atr.pools)
    pfa: float = 0.05  # false-alarm rate at which the probability of detection is read

    def validate(self) -> "AtrConfig":
        check_size(self.size)
        if self.net not in classifier.NETS:
            raise SasmiError(f"--net {self.net}: choose one of {', '.join(classifier.NETS)}")
        unknown = [w for w in self.ways if w not in WAYS]
        if unknown or not self.ways:
            raise SasmiError(f"--ways {' '.join(self.ways)}: choose from {', '.join(WAYS)}")
        return self


@dataclass(frozen=True)
class Pools:
    train_targets: Pool
    train_negatives: Pool
    test_targets: Pool
    test_negatives: Pool
    syn_targets: Pool
    syn_negatives: Pool | None


def load_pools(real_train: Path, real_test: Path, synthetic: Path, synthetic_negatives: Path | None,
               negatives: Path | None, cfg: AtrConfig) -> tuple[Pools, dict]:
    """Every pool, with the real negatives of the targets' sonar; and a note of what was filtered."""
    train_t, test_t = real_train / "targets", real_test / "targets"
    train_n, test_n = negatives or real_train / "seafloor", real_test / "seafloor"
    pools = {"train_targets": load_pool(train_t, cfg.size, "--real-train"),
             "train_negatives": load_pool(train_n, cfg.size, "--negatives" if negatives else "--real-train"),
             "test_targets": load_pool(test_t, cfg.size, "--real-test"),
             "test_negatives": load_pool(test_n, cfg.size, "--real-test")}
    wanted = target_sonars(train_t, test_t) if cfg.same_sonar else set()
    before = {k: len(pools[k]) for k in ("train_negatives", "test_negatives")}
    pools["train_negatives"] = same_sonar(pools["train_negatives"], train_n, wanted, "--real-train")
    pools["test_negatives"] = same_sonar(pools["test_negatives"], test_n, wanted, "--real-test")
    syn_t, syn_n = split_folders(synthetic)
    syn_n = synthetic_negatives or syn_n
    pools["syn_targets"] = load_pool(syn_t, cfg.size, "--synthetic")
    pools["syn_negatives"] = load_pool(syn_n, cfg.size, "--synthetic-negatives") if syn_n else None
    note = {"sonars": sorted(wanted), "negatives_before_filter": before}
    return Pools(**pools), note


def _draw(pool: Pool, n: int | None, rng: np.random.Generator) -> np.ndarray:
    images = pool.images
    return images if n is None or n >= len(images) else images[rng.choice(len(images), n, replace=False)]


def _join(*parts: np.ndarray | None) -> np.ndarray:
    return np.concatenate([p for p in parts if p is not None and len(p)])


def train_arm(way: str, n: int | None, pools: Pools, seed: int, cfg: AtrConfig, device="cpu"):
    """The network of one arm: `way` at `n` real chips per class, on the real draw of `seed`."""
    rng = np.random.default_rng(seed)  # the same real draw for every way at this n and seed
    real_t, real_n = _draw(pools.train_targets, n, rng), _draw(pools.train_negatives, n, rng)
    if n == 0:
        real_n = pools.train_negatives.images  # no real target: negatives, cheap in any survey, all
    syn_t = pools.syn_targets.images
    syn_n = pools.syn_negatives.images if pools.syn_negatives is not None else None
    fit = dict(steps=cfg.steps, seed=seed, net=cfg.net, batch=cfg.batch, lr=cfg.lr, device=device)
    if way == "real":
        return classifier.train(real_t, real_n, **fit)
    if way == "mixed":
        return classifier.train(_join(real_t, syn_t), _join(real_n, syn_n), **fit)
    if way == "alone":
        return classifier.train(syn_t, _join(real_n, syn_n), **fit)
    syn_n = syn_n if syn_n is not None else real_n
    pretrained = classifier.train(syn_t, syn_n, **fit)
    return classifier.train(real_t, real_n, **fit, model=pretrained,
                            replay=(syn_t, syn_n) if way == "replay" else None)


def arms(cfg: AtrConfig) -> list[tuple[int | None, str]]:
    """(real per class, way) of every arm that means something: at 0, only `alone`."""
    return [(n, w) for n in cfg.real_per_class for w in cfg.ways if n != 0 or w == "alone"]


def score(model, targets: np.ndarray, negatives: np.ndarray, pfa: float) -> dict:
    from sklearn.metrics import roc_auc_score

    p_t, p_n = classifier.predict(model, targets), classifier.predict(model, negatives)
    threshold = np.quantile(p_n, 1.0 - pfa)  # the score that pfa of the negatives exceed
    y = np.r_[np.ones(len(p_t)), np.zeros(len(p_n))]
    p = np.r_[p_t, p_n]
    return {"accuracy": float(((p > 0.5) == y).mean()), "auc": float(roc_auc_score(y, p)),
            "pd": float((p_t > threshold).mean())}


def key(n: int | None) -> str:
    return "all" if n is None else str(n)


def _settings(cfg: AtrConfig) -> dict:
    """What every run of one bench shares (more seeds, counts or ways extend it)."""
    return json.loads(json.dumps({k: v for k, v in asdict(cfg).items() if k not in ("seeds", "real_per_class", "ways")}))


def read_runs(path: Path) -> tuple[dict, dict[tuple[str, str, int], dict]]:
    """RUN/runs.jsonl: its first line (the bench's settings and inputs; {} for an empty file) and its runs by
    (real chips per class, way, seed)."""
    lines = []
    for line in path.read_text().splitlines():
        try:
            lines.append(json.loads(line))
        except json.JSONDecodeError:
            continue  # a line cut short by a kill: that run is trained again
    head, *rows = lines or [{}]
    return head, {(r["n"], r["way"], r["seed"]): r for r in rows}


def _done_runs(path: Path, cfg: AtrConfig, inputs: dict) -> dict[tuple[str, str, int], dict]:
    """Runs of an earlier call with the same settings; a RUN made with others is refused."""
    if not path.is_file():
        return {}
    head, runs = read_runs(path)
    if not head:
        return {}
    if head.get("settings") != _settings(cfg) or head.get("inputs") != inputs:
        raise SasmiError(f"--out {path.parent}: holds a bench of other settings or inputs; choose another --out")
    return runs


def atr_bench(real_train, real_test, synthetic, out, cfg: AtrConfig = AtrConfig(),
              synthetic_negatives=None, negatives=None, device="cpu") -> dict:
    cfg.validate()
    real_train, real_test, synthetic, out = Path(real_train), Path(real_test), Path(synthetic), Path(out)
    synthetic_negatives = Path(synthetic_negatives) if synthetic_negatives else None
    negatives = Path(negatives) if negatives else None
    pools, note = load_pools(real_train, real_test, synthetic, synthetic_negatives, negatives, cfg)
    inputs = {"real_train": str(real_train), "real_test": str(real_test), "synthetic": str(synthetic),
              "synthetic_negatives": str(synthetic_negatives or ""), "negatives": str(negatives or "")}
    lock = FolderLock(out, "running sasmi atr-bench")  # two benches in one folder would train every run twice
    try:
        return _bench(pools, note, inputs, out, cfg, device)
    finally:
        lock.release()


def _bench(pools, note: str, inputs: dict, out: Path, cfg: AtrConfig, device) -> dict:
    runs_path = out / "runs.jsonl"
    done = _done_runs(runs_path, cfg, inputs)
    if not done:
        write_text(runs_path, json.dumps({"settings": _settings(cfg), "inputs": inputs}) + "\n")
    elif not runs_path.read_text().endswith("\n"):
        with runs_path.open("a") as f:
            f.write("\n")  # end the line a kill cut short, so the next run starts a line of its own
    todo = [(n, w, s) for n, w in arms(cfg) for s in range(cfg.seeds)]
    for i, (n, way, seed) in enumerate(todo):
        if (key(n), way, seed) in done:
            continue
        model = train_arm(way, n, pools, seed, cfg, device)
        row = {"n": key(n), "way": way, "seed": seed,
               **score(model, pools.test_targets.images, pools.test_negatives.images, cfg.pfa)}
        with runs_path.open("a") as f:  # one whole line per run: a kill loses at most the run in hand
            f.write(json.dumps(row) + "\n")
        done[(row["n"], way, seed)] = row
        print(f"atr-bench: [{i + 1}/{len(todo)}] real per class {row['n']}, {way}, seed {seed}: "
              f"accuracy {row['accuracy']:.3f}, AUC {row['auc']:.3f}, Pd {row['pd']:.3f}", file=sys.stderr, flush=True)

    rows = [done[(key(n), w, s)] for n, w, s in todo]
    counts = {k: len(getattr(pools, k)) for k in ("train_targets", "train_negatives", "test_targets",
                                                  "test_negatives", "syn_targets")}
    counts["syn_negatives"] = len(pools.syn_negatives) if pools.syn_negatives is not None else 0
    results = summarise(rows)
    comparisons = paired(rows, [key(n) for n in cfg.real_per_class], YARDSTICK)
    metrics = {"config": {**asdict(cfg), "real_per_class": [key(n) for n in cfg.real_per_class]},
               "inputs": inputs, "counts": counts, "negatives": note, "results": results, "paired": comparisons}
    write_text(out / "metrics.json", json.dumps(metrics, indent=2) + "\n")
    write_text(out / "table.md", table_markdown(results, comparisons))
    plot(results, out / "atr_bench.png")
    return metrics
