"""The ATR bench's runs as figures: means with 95 % intervals, paired differences, a table, a plot.

Every way at a given number of real chips per class trains on the same real draw per seed, so
a way is judged by its differences from `real`, seed by seed: a mean difference whose 95 %
interval (Student's t over seeds) excludes 0 is an effect, whatever the spread of either arm.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

METRICS = ("accuracy", "auc", "pd")
NAMES = {"accuracy": "accuracy", "auc": "ROC AUC", "pd": "Pd at the false-alarm rate"}


def interval(values: list[float]) -> dict:
    from scipy import stats

    v = np.asarray(values, dtype=float)
    half = float(stats.t.ppf(0.975, len(v) - 1) * v.std(ddof=1) / np.sqrt(len(v))) if len(v) > 1 else None
    return {"mean": float(v.mean()), "std": float(v.std()), "ci95": half, "values": [float(x) for x in v]}


def summarise(rows: list[dict]) -> dict:
    """{real per class: {way: {metric: mean, std, 95 % half-interval, values by seed}}}."""
    out: dict = {}
    for n in dict.fromkeys(r["n"] for r in rows):
        out[n] = {}
        for way in dict.fromkeys(r["way"] for r in rows if r["n"] == n):
            runs = sorted((r for r in rows if r["n"] == n and r["way"] == way), key=lambda r: r["seed"])
            out[n][way] = {m: interval([r[m] for r in runs]) for m in METRICS}
    return out


def _partner(n: str, ns: list[str], yardstick: int) -> str | None:
    """The `real` arm a way at n is paired with: real at n, and at 0 real at the yardstick (or nearest)."""
    if n != "0":
        return n
    counts = [int(k) for k in ns if k not in ("0", "all")]
    if counts:
        return str(min(counts, key=lambda k: abs(k - yardstick)))
    return "all" if "all" in ns else None


def paired(rows: list[dict], ns: list[str], yardstick: int) -> list[dict]:
    """Per way and count: the mean difference from `real` seed by seed, with its 95 % interval."""
    by = {(r["n"], r["way"], r["seed"]): r for r in rows}
    out = []
    for n in ns:
        against = _partner(n, ns, yardstick)
        for way in dict.fromkeys(r["way"] for r in rows if r["n"] == n and r["way"] != "real"):
            seeds = sorted(s for (k, w, s) in by if k == n and w == way and (against, "real", s) in by)
            if not seeds:
                continue
            diffs = {m: interval([by[(n, way, s)][m] - by[(against, "real", s)][m] for s in seeds]) for m in METRICS}
            out.append({"n": n, "way": way, "against": f"real at {against}", "seeds": len(seeds), **diffs})
    return out


def _pm(m: dict) -> str:
    return f"{m['mean']:.3f}" + ("" if m["ci95"] is None else f" ± {m['ci95']:.3f}")


def table_markdown(results: dict, comparisons: list[dict]) -> str:
    lines = ["| real chips per class | way | accuracy | ROC AUC | Pd at Pfa |", "|---|---|---:|---:|---:|"]
    for n, ways in results.items():
        for way, m in ways.items():
            lines.append(f"| {n} | {way} | " + " | ".join(_pm(m[k]) for k in METRICS) + " |")
    lines += ["", "Paired differences from `real` (same real draw per seed), mean and 95 % interval:", "",
              "| real chips per class | way | against | seeds | Δ accuracy | Δ ROC AUC | Δ Pd |",
              "|---|---|---|---:|---:|---:|---:|"]
    for c in comparisons:
        cells = [f"{c[k]['mean']:+.3f}" + ("" if c[k]["ci95"] is None else
                                          f" [{c[k]['mean'] - c[k]['ci95']:+.3f}, {c[k]['mean'] + c[k]['ci95']:+.3f}]")
                 for k in METRICS]
        lines.append(f"| {c['n']} | {c['way']} | {c['against']} | {c['seeds']} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def plot(results: dict, path: Path) -> None:
    """ROC AUC against real chips per class, a curve per way with its 95 % interval."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from sasmi.images import atomic_path

    ns = list(results)
    x = np.arange(len(ns))
    fig, ax = plt.subplots(figsize=(5.5, 3.6))
    for way in dict.fromkeys(w for n in ns for w in results[n]):
        pts = [(i, results[n][way]["auc"]) for i, n in enumerate(ns) if way in results[n]]
        xs = [i for i, _ in pts]
        ax.errorbar(xs, [m["mean"] for _, m in pts], yerr=[m["ci95"] or 0.0 for _, m in pts], marker="o", capsize=3,
                    label=way)
    ax.set_xticks(x, ns)
    ax.set_xlabel("real chips per class")
    ax.set_ylabel("ROC AUC on real test chips")
    ax.legend(fontsize=8, loc="lower right")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=100)
    plt.close(fig)
