"""Render | translation | nearest real chip (in φ) for a dozen chips: the README's GAN figures.

    .venv/bin/python benchmarks/triptych.py --renders RUN/renders --translated RUN/translated \
        --real SPLIT/validation/targets --phi RUN/phi --out docs/figures/sasgan_triptych.png [--count 12] \
        [--on-floors RUN/on_floors]

RUN is a `sasmi fit` run folder, SPLIT the folder `sasmi split` wrote.

With --on-floors (a `sasmi fit` run with real floors) a row between render and translation shows
the render on its real floor, the GAN's input.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from sasmi.eval.features import as_encoder, load_set
from sasmi.images import list_images, read_gray


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--renders", type=Path, required=True)
    ap.add_argument("--translated", type=Path, required=True)
    ap.add_argument("--real", type=Path, required=True)
    ap.add_argument("--phi", type=Path, required=True)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--count", type=int, default=12)
    ap.add_argument("--on-floors", type=Path, help="the renders on real floors (RUN/on_floors), shown as a row")
    args = ap.parse_args()

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from sasmi.eval.report import save_figure

    encoder = as_encoder(args.phi)
    real = load_set("real", args.real, encoder)
    translated = load_set("translated", args.translated, encoder)
    names = [p.stem for p in list_images(args.translated)]
    renders = {p.stem: p for p in list_images(args.renders)}  # a translation keeps its render's name
    picks = np.linspace(0, len(names) - 1, args.count).round().astype(int)
    d = ((translated.phi[picks, None, :] - real.phi[None, :, :]) ** 2).sum(-1)  # (count, N_real)
    nearest = d.argmin(1)

    on_floors = {p.stem: p for p in list_images(args.on_floors)} if args.on_floors else {}
    rows = 3 + bool(on_floors)
    fig, axes = plt.subplots(rows, args.count, figsize=(1.3 * args.count, 1.37 * rows))
    for col, (i, j) in enumerate(zip(picks, nearest)):
        shown = [(read_gray(renders[names[i]]), "render")]
        if on_floors:
            shown.append((read_gray(on_floors[names[i]]), "on a real floor"))
        shown += [(translated.image(i), "translation"), (real.image(j), "nearest real")]
        for row, (image, title) in enumerate(shown):
            ax = axes[row, col]
            ax.imshow(image, cmap="gray", vmin=0, vmax=1)
            ax.set_xticks([])
            ax.set_yticks([])
            if col == 0:
                ax.set_ylabel(title, fontsize=9)
    fig.tight_layout(pad=0.2)
    save_figure(fig, args.out)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
