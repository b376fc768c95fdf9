"""`sasmi stats` output: the side-by-side table, tolerances against a reference, JSON and the figure.

`results` below is a list of sasmi.chips.stats.chip_statistics dictionaries; the first is the
reference (usually the real chips) that the others are divided by and checked against.
"""
from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sasmi.images import atomic_path, write_text
from sasmi.chips.stats import MASK_STATISTICS, STATISTICS


@dataclass(frozen=True)
class Tolerance:
    """A statistic matches when other/reference lies in [low, high] ("ratio"), |other - reference| <= high
    ("diff") or other <= high ("max")."""
    kind: str
    low: float
    high: float

    def holds(self, reference: float, other: float) -> bool:
        if not (math.isfinite(reference) and math.isfinite(other)):
            return False
        if self.kind == "ratio":
            if reference <= 0 or other <= 0:
                return reference == other == 0  # a statistic both lack (no gain swing) matches
            return self.low <= other / reference <= self.high
        if self.kind == "diff":
            return abs(other - reference) <= self.high
        return other <= self.high

    def distance(self, reference: float, other: float) -> float:
        """How many tolerances `other` lies from `reference`: <= 1 where `holds`, inf where either is
        missing. A ratio counts on a log scale: half and double the reference are equally far; two zeros match."""
        if not (math.isfinite(reference) and math.isfinite(other)):
            return math.inf
        if self.kind == "ratio":
            if reference <= 0 or other <= 0:
                return 0.0 if reference == other == 0 else math.inf
            r = math.log(other / reference)
            return r / math.log(self.high) if r >= 0 else r / math.log(self.low)
        if self.kind == "diff":
            return abs(other - reference) / self.high
        return max(other, 0.0) / self.high

    def describe(self) -> str:
        return {"ratio": f"{self.low:g}-{self.high:g}x", "diff": f"±{self.high:g}", "max": f"<= {self.high:g}"}[self.kind]


# How close a preset's medians over chips must come to the real chips' to count as matching
# (docs/matching.md, *Tolerances and why*).
TOLERANCES = {
    **{k: Tolerance("ratio", 0.67, 1.5) for k in MASK_STATISTICS},
    "looks": Tolerance("ratio", 0.7, 1.4),
    "p50": Tolerance("diff", 0.0, 12.0),
    "p99": Tolerance("diff", 0.0, 25.0),
    "saturated": Tolerance("max", 0.0, 0.5),
    "acf_range": Tolerance("diff", 0.0, 0.07),
    "acf_track": Tolerance("diff", 0.0, 0.07),
    "far_near": Tolerance("diff", 0.0, 0.07),
    # stripes such as sand ripples, which no real chip has, escape φ; 1.5x sits between the real chips'
    # spread and a rippled floor's median (docs/matching.md, *Tolerances and why*)
    "periodicity": Tolerance("ratio", 0.67, 1.5),
}


# More that `sasmi calibrate` matches on target chips: shadows may be pale where found, and real target chips are
# cut centred on the contact along track and nearer than the centre along range, so that its shadow falls in the
# chip (offsets in px at the statistics' size; the shared MILCO train targets' quartiles at 128 px: 0.5-2 along
# track, -11.2 to -8.5 along range)
TARGET_EXTRAS = {"shadow_floor": Tolerance("ratio", 0.67, 1.5), "offset_track": Tolerance("diff", 0.0, 1.5),
                 "offset_range": Tolerance("diff", 0.0, 1.5)}
# and on every chip: the swath's gain swinging from ping to ping, which bands target and floor chips alike, the
# speckle's contrast wandering from patch to patch, which a classifier tells at once where it is missing (the shared
# MILCO train and validation targets' medians differ by 7 %, so 1.25x), and the seabed's contrast above the speckle,
# which a classifier tells where sand waves and sediments are fainter than real ones (train and validation medians:
# MILCO targets 8 % apart, MILCO floors 4 %, SASSED floors 19 %)
EVERY_CHIP_EXTRAS = {"bands": Tolerance("ratio", 0.67, 1.5), "wander": Tolerance("ratio", 0.8, 1.25),
                     "seabed": Tolerance("ratio", 0.8, 1.25)}


def check(reference: dict, other: dict) -> dict[str, bool]:
    """statistic -> whether `other`'s median is within TOLERANCES of `reference`'s."""
    return {k: tol.holds(reference["summary"][k]["median"], other["summary"][k]["median"])
            for k, tol in TOLERANCES.items()}


WHOLE_NUMBERS = (*MASK_STATISTICS, "p50", "p99")


def _number(x: float, key: str) -> str:
    if not math.isfinite(x):
        return "—"
    if key in WHOLE_NUMBERS:
        return f"{x:.0f}"
    if key == "bands":
        return f"{x:.3f}"
    return f"{x:.1f}" if key in ("looks", "periodicity", "offset_track", "offset_range") else f"{x:.2f}"


def column_names(results: list[dict]) -> list[str]:
    """Folder names, with the parent added where two folders share a name."""
    names = [Path(r["folder"]).name or r["folder"] for r in results]
    return [f"{Path(r['folder']).parent.name}/{n}" if names.count(n) > 1 else n for r, n in zip(results, names)]


def table(results: list[dict], with_check: bool = False) -> str:
    """A Markdown table: one row per statistic, per folder `median [q25, q75]` and its ratio to the first."""
    names = column_names(results)
    head = ["statistic"] + [f"{n} (n={len(r['chips'])})" for n, r in zip(names, results)]
    if with_check:
        head.append("tolerance")
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    ref = results[0]
    for key, (label, unit) in STATISTICS.items():
        row = [f"{label} ({unit})" if unit else label]
        for i, r in enumerate(results):
            s = r["summary"][key]
            cell = f"{_number(s['median'], key)} [{_number(s['q25'], key)}, {_number(s['q75'], key)}]"
            if s["n"] != len(r["chips"]):  # target statistics: only chips where a target was found
                cell += f" (n={s['n']})"
            base = ref["summary"][key]["median"]
            if i and math.isfinite(base) and base != 0 and math.isfinite(s["median"]):
                cell += f" x{s['median'] / base:.2f}"
            if i and with_check and key in TOLERANCES:
                cell += " **ok**" if check(ref, r)[key] else " **FAIL**"
            row.append(cell)
        if with_check:
            row.append(TOLERANCES[key].describe() if key in TOLERANCES else "")
        lines.append("| " + " | ".join(row) + " |")
    found = ["targets found (highlight + shadow)"] + [f"{100 * r['targets_found']:.0f} %" for r in results]
    lines.append("| " + " | ".join(found + ([""] if with_check else [])) + " |")
    if any("mask_error" in r for r in results):
        for key in MASK_STATISTICS:
            part = STATISTICS[key][0].replace("highlight", "highlight vs target mask")
            row = [f"median abs(image - mask): {part} (px)"]
            row += [_number(r["mask_error"][key], "looks") if "mask_error" in r else "" for r in results]
            lines.append("| " + " | ".join(row + ([""] if with_check else [])) + " |")
    return "\n".join(lines)


def _plain(x):
    if isinstance(x, dict):
        return {k: _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple, np.ndarray)):
        return [_plain(v) for v in (x.tolist() if isinstance(x, np.ndarray) else x)]
    if isinstance(x, (float, np.floating)):
        return float(x) if math.isfinite(x) else None
    if isinstance(x, np.integer):
        return int(x)
    return x


def write_json(results: list[dict], path: str | os.PathLike) -> None:
    """Every folder's per-chip values and summary (NaN as null), plus the tolerance check against the first."""
    doc = {"folders": _plain(results),
           "check_against_first": [_plain(check(results[0], r)) for r in results[1:]],
           "tolerances": {k: t.describe() for k, t in TOLERANCES.items()}}
    write_text(path, json.dumps(doc, indent=1, allow_nan=False) + "\n")


def plot(results: list[dict], path: str | os.PathLike) -> None:
    """Histograms of every statistic over chips, one colour per folder, and bars of median / first folder."""
    from matplotlib.figure import Figure

    names = column_names(results)
    keys = list(STATISTICS)
    rows = math.ceil((len(keys) + 1) / 4)  # a histogram per statistic, and the bars
    fig = Figure(figsize=(16, 3.25 * rows))
    axes = fig.subplots(rows, 4).ravel()
    for ax, key in zip(axes, keys):
        values = [r["per_chip"][key][np.isfinite(r["per_chip"][key])] for r in results]
        pooled = np.concatenate(values) if any(v.size for v in values) else np.zeros(1)
        low, high = np.percentile(pooled, [1, 99])  # a few flat chips give looks in the hundreds
        bins = np.linspace(low, high if high > low else low + 1, 31)
        for name, v in zip(names, values):
            if v.size:
                ax.hist(v, bins=bins, histtype="step", density=True, linewidth=1.5, label=f"{name} ({v.size})")
        label, unit = STATISTICS[key]
        ax.set_title(f"{label}" + (f" ({unit})" if unit else ""), fontsize=9)
    axes[0].legend(fontsize=7)
    bars = axes[len(keys)]
    width = 0.8 / max(1, len(results) - 1)
    for j, (name, r) in enumerate(zip(names[1:], results[1:])):
        ratios = [r["summary"][k]["median"] / results[0]["summary"][k]["median"]
                  if results[0]["summary"][k]["median"] else np.nan for k in keys]
        bars.bar(np.arange(len(keys)) + j * width, ratios, width=width, label=name, color=f"C{j + 1}")
    bars.axhline(1.0, color="k", linewidth=0.8)
    bars.set_yscale("log")
    bars.set_xticks(np.arange(len(keys)), keys, rotation=90, fontsize=7)
    bars.set_title(f"median / median of {names[0]}", fontsize=9)
    for ax in axes[len(keys) + 1:]:
        ax.axis("off")
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=80, format=Path(path).suffix.lstrip(".") or "png")
