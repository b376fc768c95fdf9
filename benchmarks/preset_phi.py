"""Which scene parameters put a preset's renders off the real chips in φ: a guide for tuning a preset.

For every render of a labelled render set, "on the real manifold" means inside some real
chip's k-NN ball in φ (the chips `sasmi evaluate`'s precision counts). Each numeric scene
parameter is cut at its quartiles, and the table gives the share of renders on the
manifold per quartile (and per value for kinds of target), the parameters that matter
most first: a parameter whose top quartile scores far below its bottom one is drawing
chips that no real chip looks like. Narrow it, render again, and check with `sasmi
evaluate` that recall holds (a preset can buy precision by losing variety).

    .venv/bin/python benchmarks/preset_phi.py RENDERS --real SPLIT/train/targets --phi RUN/phi [--k 3]

Tune on train chips only (`sasmi split`); report on validation.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))


def parameter_columns(labels) -> dict[str, np.ndarray]:
    """Scene parameter name -> (N,) values over the render set: sonar, seafloor, post, first target."""
    columns: dict[str, list] = {}
    for label in labels:
        for section in ("sonar", "seafloor", "post"):
            for name, value in label.scene.get(section, {}).items():
                if isinstance(value, (int, float)) and not isinstance(value, bool):
                    columns.setdefault(f"{section}.{name}", []).append(value)
        target = label.targets[0] if label.targets else None
        columns.setdefault("target.shape", []).append(target.params["shape"] if target else "none")
        for name in ("x", "y", "yaw", "burial"):
            columns.setdefault(f"target.{name}", []).append(target.params.get(name, np.nan) if target else np.nan)
        columns.setdefault("target.shadow_pixels", []).append(target.shadow_pixels if target else 0)
    return {name: np.asarray(values) for name, values in columns.items() if len(values) == len(labels)}


def breakdown(values: np.ndarray, on_real: np.ndarray) -> tuple[float, str]:
    """(spread of the on-manifold share across groups, one table cell) for one parameter."""
    if values.dtype.kind not in "fi":
        groups = [(str(v), values == v) for v in np.unique(values)]
    else:
        finite = np.isfinite(values)
        if not finite.any() or np.ptp(values[finite]) == 0:
            return 0.0, ""
        edges = np.quantile(values[finite], [0, 0.25, 0.5, 0.75, 1])
        quartile = np.clip(np.searchsorted(edges[1:-1], values, side="right"), 0, 3)
        groups = [(f"{edges[q]:.3g}-{edges[q + 1]:.3g}", finite & (quartile == q)) for q in range(4)]
    shares = [(name, on_real[member].mean(), member.sum()) for name, member in groups if member.any()]
    spread = max(s for _, s, _ in shares) - min(s for _, s, _ in shares)
    return spread, "  ".join(f"{name}: {share:.2f} ({n})" for name, share, n in shares)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("renders", type=Path, help="a render set (images/ and labels/)")
    ap.add_argument("--real", type=Path, required=True, help="real chips (train split)")
    ap.add_argument("--phi", type=Path, required=True, help="autoencoder run (sasmi train autoencoder)")
    ap.add_argument("--k", type=int, default=3, help="neighbours that set a real chip's ball (as evaluate's precision)")
    args = ap.parse_args()

    from sasmi.eval.features import as_encoder, load_set
    from sasmi.eval.manifold import on_manifold
    from sasmi.gan.autoencoder import load_encoder
    from sasmi.labels import read_labels

    encoder = as_encoder(load_encoder(args.phi, "cpu"))
    real = load_set("real", args.real, encoder)
    renders = load_set("renders", args.renders / "images", encoder)
    labels = sorted(read_labels(args.renders), key=lambda label: label.index)
    if len(labels) != len(renders.phi):
        raise SystemExit(f"{args.renders}: {len(labels)} labels for {len(renders.phi)} images")
    on_real = on_manifold(renders.phi, real.phi, args.k)  # as sasmi evaluate's precision counts them
    print(f"{len(labels)} renders, {len(real.phi)} real chips: {on_real.mean():.2f} of the renders on the "
          f"real manifold (precision, k={args.k}); share per quartile (count), parameters that matter most first")
    rows = [(name, *breakdown(values, on_real)) for name, values in parameter_columns(labels).items()]
    for name, spread, cell in sorted(rows, key=lambda row: -row[1]):
        if cell:
            print(f"{name:28s} spread {spread:.2f}   {cell}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
