"""The report: sections of markdown, metrics.json, and every figure. Text and plots only.

Each part of the evaluation computes its numbers elsewhere (metrics, neighbours,
preservation, sweeps) and hands them here to be written; figures are saved next to
report.md and referenced from it by file name. matplotlib is imported inside the
functions that draw, so importing this module stays fast.
"""
from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from sasmi.eval.config import EvalConfig, PreservationConfig
from sasmi.eval.features import FeatureSet
from sasmi.images import atomic_path, write_text
from sasmi.labels import TargetLabel
from sasmi.masks import SEAFLOOR as MASK_SEAFLOOR, SHADOW as MASK_SHADOW, TARGET as MASK_TARGET

REAL_VS_REAL = "real→real"


@dataclass(frozen=True)
class Section:
    title: str
    body: str  # markdown; figures are referenced by file name, saved next to report.md


@dataclass(frozen=True)
class Report:
    metrics: dict  # JSON-ready; each part of the evaluation owns one top-level key
    sections: tuple[Section, ...]

    def __add__(self, other: "Report") -> "Report":
        return Report({**self.metrics, **other.metrics}, self.sections + other.sections)


def pm(value: float, std: float, fmt: str) -> str:
    """'value ± std', or just the value where no spread was measured."""
    return f"{value:{fmt}} ± {std:{fmt}}" if math.isfinite(std) else f"{value:{fmt}}"


def mean_share(row: dict) -> str:
    """The mean part of a row's FID as a percentage (`—` where FID is 0)."""
    if not row["fid"] > 0:
        return "—"
    return f"{100 * row['fid_mean_part'] / row['fid']:.0f} %"


def realism_markdown(rows: dict, real: FeatureSet) -> str:
    lines = [f"Real set: `{real.folder}` ({len(real.phi)} images). φ: {real.phi.shape[1]} dimensions at "
             f"{real.images.shape[-1]}² px. Each row compares its set with the real set; {REAL_VS_REAL} compares "
             "two disjoint random halves of the real set, the floor any generator can reach at that sample size.",
             "",
             "| set | images | φ-FID | ÷ real→real | from the means | KID ×10³ | precision | recall | gray levels ×10³ |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for name, r in rows.items():
        n = " + ".join(map(str, r["n"])) if isinstance(r["n"], list) else str(r["n"])
        lines.append(f"| {name} | {n} | {pm(r['fid'], r['fid_std'], '.3g')} | {pm(r['fid_ratio'], r['fid_ratio_std'], '.2f')} | "
                     f"{mean_share(r)} | {pm(r['kid'] * 1e3, r['kid_std'] * 1e3, '.3f')} | "
                     f"{pm(r['precision'], r['precision_std'], '.2f')} | {pm(r['recall'], r['recall_std'], '.2f')} | "
                     f"{r['gray_levels'] * 1e3:.0f} |")
    lines += ["", "- **φ-FID**: the set against the whole real set, ± the std over bootstrap resamples; real→real "
              "is the mean ± std over random splits of the real set into halves.",
              "- **÷ real→real**: FID of the set against a random real half B divided by FID of the other half A "
              "against B, with the set and A drawn to the same size, so that FID's small-sample bias cancels "
              "(raw FIDs at different sample sizes are not comparable); mean over random splits ± the std of "
              "the per-split ratios. About 1 means as close to the real images as real images are to each other.",
              "- **from the means**: the share of φ-FID that is ‖μ_set − μ_real‖², what one shift of every "
              "image's φ would remove (the set differs on average: gray level, texture); the rest is how the "
              "sets spread (which scenes occur, their variety), which a per-image correction hardly reaches.",
              "- **gray levels**: energy distance between the chips' gray-level distributions (27 quantiles of "
              "each chip, its bright tail included) and the real chips', without φ; ≈ 0 (it can be negative) "
              "when each chip's levels could be a real chip's. real→real: its two halves.",
              "- **KID**: unbiased MMD² with the cubic polynomial kernel on φ divided by the real set's rms entry, "
              "mean ± std over random subsets; ≈ 0 (it can be negative) when the set looks real, reliable for "
              "small sets.",
              "- **precision / recall**: share of the set inside the real k-NN manifold, and of the real set "
              "inside the set's (k = 3), both sets drawn to the same size (a ball shrinks as its set grows), "
              "mean ± std over random draws. Precision is realism, recall is diversity.",
              "",
              "Lower FID, ratio and KID and higher precision and recall are more realistic."]
    return "\n".join(lines)


def copying_markdown(copying: dict, sets: Sequence[FeatureSet], cfg: EvalConfig) -> str:
    p = cfg.copy_percentile
    lines = ["For each generated image, the distance to its nearest real image, compared with the distance of "
             "each real image to its nearest *other* real image. Pixel distance is the rms gray-level difference "
             "(0–1) at the encoder's size. A generator that copies training images shows a median ratio well "
             f"below 1 and far more than {p:g} % of its images below the real→real {p:g}th percentile.", "",
             f"| set | pixel: median ratio | pixel: below p{p:g} | φ: median ratio | φ: below p{p:g} |",
             "|---|---:|---:|---:|---:|"]
    for s in sets:
        c = copying[s.name]
        lines.append(f"| {s.name} | {c['pixel']['median_ratio']:.2f} | {100 * c['pixel']['fraction_below']:.1f} % | "
                     f"{c['phi']['median_ratio']:.2f} | {100 * c['phi']['fraction_below']:.1f} % |")
    lines += ["", "![nearest distances](nearest_distances.png)", ""]
    for s in sets:
        lines += [f"**{s.name}**: first column a generated image, then its {cfg.neighbours_k} nearest real images "
                  f"in pixel ℓ2, then in φ (distance above each).", "",
                  f"![neighbours of {s.name}](neighbours_{s.name}.png)", ""]
    return "\n".join(lines)


def coverage_markdown(coverage: dict, figure: str) -> str:
    lines = ["Recall chip by chip: for each real chip, the share of draws of a set (at the real set's size, as "
             "for recall) whose k-NN balls hold it. Its mean is the set's recall; a real chip at 0 looks like "
             "none of the set's chips. The least covered real chips of each set, each beside its nearest chip "
             "of the set in φ:", "",
             "| set | mean coverage (recall) | real chips never covered | least covered |", "|---|---:|---:|---|"]
    for name, c in coverage.items():
        least = ", ".join(f"{x['chip']} ({x['covered']:.2f})" for x in c["least"][:3])
        lines.append(f"| {name} | {c['mean']:.2f} | {c['never']} | {least} |")
    lines += ["", f"![least covered real chips]({figure})", ""]
    return "\n".join(lines)


def statistics_markdown(rows: dict[str, dict]) -> str:
    """A table with one row per set and one column per statistic (in order of first appearance)."""
    columns = list(dict.fromkeys(key for row in rows.values() for key in row))

    def cell(v) -> str:
        return f"{v:.4g}" if isinstance(v, (float, np.floating)) else str(v)

    lines = ["| set | " + " | ".join(columns) + " |", "|---|" + "---:|" * len(columns)]
    lines += [f"| {name} | " + " | ".join(cell(row[c]) if c in row else "" for c in columns) + " |"
              for name, row in rows.items()]
    return "\n".join(lines)


def save_figure(fig, path: Path) -> None:
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, bbox_inches="tight")


def neighbour_grid(s: FeatureSet, real: FeatureSet, shown: np.ndarray, pixel: tuple, phi: tuple, path: Path) -> None:
    """Rows: a generated image, its k nearest real images in pixel ℓ2, then in φ."""
    rows = []
    for i in shown:
        cells = [(s.image(i), s.name)]
        cells += [(real.image(j), f"px {d:.3f}") for j, d in zip(pixel[0][i], pixel[1][i])]
        cells += [(real.image(j), f"φ {d:.3g}") for j, d in zip(phi[0][i], phi[1][i])]
        rows.append(cells)
    k = pixel[0].shape[1]
    mosaic_figure(rows, path, gaps_before=(1, 1 + k))


def mosaic_figure(rows: Sequence[Sequence[tuple[np.ndarray, str]]], path: Path, gaps_before: Sequence[int] = ()) -> None:
    """A grid of (image (S, S) in [0, 1], caption) cells drawn as one image: one imshow is
    ~10× faster to save than a subplot per cell. A wider gap goes before the listed columns."""
    from matplotlib.figure import Figure

    size = rows[0][0][0].shape[-1]
    zoom = max(1.0, 96 / size)  # display px per image px: small images are enlarged to stay legible
    pad, caption = max(2, size // 16), math.ceil(28 / zoom)  # caption rows fit two lines of 7 pt text
    x0 = [pad + j * (size + pad) + 2 * pad * sum(j >= g for g in gaps_before) for j in range(len(rows[0]))]
    row_step = caption + size + pad
    canvas = np.ones((len(rows) * row_step + pad, x0[-1] + size + pad), dtype=np.float32)  # white background
    for r, cells in enumerate(rows):
        top = r * row_step + caption
        for x, (image, _) in zip(x0, cells):
            canvas[top:top + size, x:x + size] = image
    fig = Figure(figsize=(canvas.shape[1] * zoom / 100, canvas.shape[0] * zoom / 100), dpi=100)
    ax = fig.add_axes((0, 0, 1, 1))
    ax.imshow(canvas, cmap="gray", vmin=0, vmax=1, interpolation="nearest")
    for r, cells in enumerate(rows):
        for x, (_, text) in zip(x0, cells):
            ax.text(x + size / 2, r * row_step + caption - 1, text, ha="center", va="bottom", fontsize=7)
    ax.set_axis_off()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=100)


def distance_histograms(real_nn: dict, generated_nn: dict, path: Path) -> None:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10, 3.5))
    for ax, space, label in zip(fig.subplots(1, 2), ("pixel", "phi"), ("rms pixel difference", "φ distance")):
        values = [real_nn[space], *(g[space] for g in generated_nn.values())]
        bins = np.linspace(0.0, max(v.max() for v in values) * 1.02 or 1.0, 40)
        ax.hist(real_nn[space], bins=bins, density=True, color="0.6", label=f"{REAL_VS_REAL} (leave one out)")
        for colour, (name, g) in enumerate(generated_nn.items(), start=1):
            ax.hist(g[space], bins=bins, density=True, histtype="step", linewidth=1.8, color=f"C{colour}",
                    label=f"{name}→real")
        ax.set_xlabel(f"nearest-neighbour {label}")
        ax.legend(fontsize=7)
    save_figure(fig, path)


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, (np.floating, float)):
        return float(x) if math.isfinite(x) else None  # JSON has no NaN/inf
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, Path):
        return str(x)
    return x


def write_report(out_dir: str | os.PathLike, report: Report, title: str = "sasmi evaluation") -> Path:
    """report.md (sections in order) and metrics.json in out_dir; returns the report path."""
    out_dir = Path(out_dir)
    body = "\n\n".join(f"## {s.title}\n\n{s.body.strip()}" for s in report.sections)
    write_text(out_dir / "report.md", f"# {title}\n\nMetric definitions: docs/evaluate.md in the sasmi "
               f"repository.\n\n{body}\n")
    write_text(out_dir / "metrics.json", json.dumps(_jsonable(report.metrics), indent=2, ensure_ascii=False) + "\n")
    return out_dir / "report.md"


def preservation_markdown(metrics: dict, skipped: list[str], cfg: PreservationConfig) -> str:
    lines = ["Measured on every set that carries a render's masks/ and labels.jsonl (a render set, or a "
             "translated render set). Compare a translated set with its render set: a translation that keeps "
             "the scene keeps these numbers.", ""]
    if metrics:
        lines += ["| set | images | shadow IoU | highlight centroid error (px) | targets lost | target contrast |",
                  "|---|---:|---:|---:|---:|---:|"]
        for name, m in metrics.items():
            lines.append(f"| {name} | {m['images']} | {m['shadow_iou']:.2f} | {m['centroid_error_px']:.1f} | "
                         f"{100 * m['lost']:.0f} % | {m['target_contrast']:.2f} |")
        lines += ["", "Medians over images (over targets for the centroid error). Definitions, with the image "
                  f"blurred by a Gaussian of σ = {cfg.smooth:g} px and *floor* its values where the mask says "
                  "seafloor:",
                  f"- **shadow IoU**: dark pixels (below {cfg.dark_fraction:g} × median floor) within "
                  f"{cfg.margin} px of the labelled target and shadow boxes, intersection over union with the "
                  "labelled shadow mask.",
                  f"- **highlight centroid error**: centroid of the brightness above the floor's "
                  f"{cfg.bright_percentile:g}th percentile within {cfg.margin} px of the target's box, distance "
                  "to the label's pixel_centre. The highlight is the sonar-facing side, so even a render is a "
                  "few px off: compare with the render set.",
                  "- **targets lost**: targets with nothing brighter than that percentile near them.",
                  "- **target contrast**: mean over the labelled target pixels / median floor.", ""]
        lines += [f"![preservation examples: {name}](preservation_{name}.png)" for name in metrics]
        lines += ["", "Examples: labelled shadow outlined in cyan, measured dark region in red, label centre as a "
                  "green +, highlight centroid as a red ×."]
    if skipped:
        lines += ["", f"Skipped (no masks/ and labels.jsonl): {', '.join(skipped)}."]
    return "\n".join(lines)


def examples_figure(items: Sequence[tuple], measures: Sequence[dict], path: Path) -> None:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(2.2 * len(items), 2.5))
    for ax, (image_path, image, mask, targets), m in zip(fig.subplots(1, len(items), squeeze=False)[0], items, measures):
        _draw_measured(ax, image, mask, targets, m, f"{image_path.stem}  IoU {m['shadow_iou']:.2f}")
    save_figure(fig, path)


def _draw_measured(ax, image: np.ndarray, mask: np.ndarray, targets: Sequence[TargetLabel], m: dict, title: str) -> None:
    ax.imshow(image, cmap="gray", vmin=0, vmax=1)
    if (mask == MASK_SHADOW).any():
        ax.contour(mask == MASK_SHADOW, levels=[0.5], colors="cyan", linewidths=0.8)
    if m["dark"].any():
        ax.contour(m["dark"], levels=[0.5], colors="red", linewidths=0.6)
    for t, c in zip(targets, m["centroids"]):
        ax.plot(*t.pixel_centre, "+", color="lime", markersize=8)
        if c is not None:
            ax.plot(*c, "x", color="red", markersize=6)
    ax.set_title(title, fontsize=7)
    ax.set_axis_off()


def sweep_grid(rendered: Sequence, targets: Sequence[Sequence[TargetLabel]], translated: np.ndarray,
               poses: Sequence[dict], path: Path) -> None:
    """Renders (top row) and their translations (bottom row), each with its measurements drawn."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(1.9 * len(poses), 4.2))
    axes = fig.subplots(2, len(poses), squeeze=False)
    for col, (r, t, out, p) in enumerate(zip(rendered, targets, translated, poses)):
        for row, (image, key) in enumerate(((r.image, "render"), (out, "translated"))):
            n = p[key]
            _draw_measured(axes[row, col], image, r.mask, t, p["measures"][row],
                           f"{p['caption'] if row == 0 else key}\nerr {n['centroid_error_px']:.1f} px  "
                           f"IoU {n['shadow_iou']:.2f}")
    save_figure(fig, path)


def tsne_figure(groups: Sequence[tuple[FeatureSet, np.ndarray, np.ndarray]], xy: np.ndarray, perplexity: float,
                path: Path) -> Section:
    """The t-SNE map. Each group is (set, indices of its points, positions among them drawn as
    thumbnails); `xy` (n, 2) holds the points of all groups in order."""
    from matplotlib.colors import Normalize
    from matplotlib.figure import Figure
    from matplotlib.offsetbox import AnnotationBbox, OffsetImage

    fig = Figure(figsize=(8, 7))
    ax = fig.add_subplot()
    start = 0
    for colour, (s, idx, thumbs) in enumerate(groups):
        pts = xy[start:start + len(idx)]
        ax.scatter(pts[:, 0], pts[:, 1], s=8, alpha=0.6, color=f"C{colour}", label=f"{s.name} ({len(idx)})")
        for j in thumbs:
            thumb = OffsetImage(s.image(idx[j]), cmap="gray", norm=Normalize(0, 1), zoom=32 / s.images.shape[-1])
            ax.add_artist(AnnotationBbox(thumb, pts[j], frameon=True, pad=0.1,
                                         bboxprops={"edgecolor": f"C{colour}", "linewidth": 1.5}))
        start += len(idx)
    ax.legend(loc="best", fontsize=8, markerscale=2)
    ax.set_xticks([])
    ax.set_yticks([])
    ax.set_title(f"t-SNE of φ (perplexity {perplexity:.0f})")
    save_figure(fig, path)
    return Section("t-SNE of φ", "Each point is one image; sets that overlap look alike to the encoder. A few "
                   f"images are drawn at their positions, framed in their set's colour.\n\n![t-SNE]({path.name})")
