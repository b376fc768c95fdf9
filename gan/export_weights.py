"""A run stripped to what loading its net needs: the weights files sasmi ships (sasmi/weights/) and any user's.

The file holds the run's config and step and the weights of WEIGHTS[kind], in the checkpoint layout
(sasmi.gan.run), so every loader reads it in place of the run folder.
"""
from __future__ import annotations

import os
from pathlib import Path

from sasmi.errors import SasmiError
from sasmi.gan.run import FORMAT, read_run
from sasmi.images import write_torch

# what loading a trained net needs of each run kind: the rest (optimisers, critic, streams) only resumes it
WEIGHTS = {"autoencoder": ("autoencoder",), "sasgan": ("generator_ema",), "dcgan": ("generator",)}


def export_weights(run_dir: str | os.PathLike, kind: str, out: str | os.PathLike, which: str = "last",
                   about: dict | None = None) -> Path:
    """A run's checkpoint stripped to the weights that loading needs (WEIGHTS), its config and step, as
    one file that the loaders read in place of the run folder; `about` (plain types) rides along."""
    from sasmi import __version__

    saved = read_run(run_dir, kind, which)
    missing = [name for name in WEIGHTS[kind] if name not in saved.state]
    if missing:
        raise SasmiError(f"{saved.path}: has no {', '.join(missing)} weights to export")
    weights = {"format": FORMAT, "sasmi": __version__, "kind": kind, "config": saved.config, "step": saved.step,
               "state": {name: saved.state[name] for name in WEIGHTS[kind]}, "about": about or {}}
    return write_torch(out, weights)
