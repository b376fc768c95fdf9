"""The reference weights sasmi ships, trained on the shared real chips (model card: docs/models.md).

- phi.pt:    the φ autoencoder every figure is measured in when no --phi is given, so that two users'
             φ-FID figures are comparable (as clean-fid fixes its Inception);
- sasgan.pt:  the SAS GAN generator (moving average) `sasmi generate` uses when no --generator is given;
- seabeds.pt: real floors' seabed statistics (sasmi.realism.seabeds): that generator's renders are laid
              on floors drawn from them, as it was trained, when no --floors is given.

phi.pt and sasgan.pt are checkpoints stripped to the weights a loader needs (sasmi.gan.export_weights);
all three load with torch.load(weights_only=True), the first two in place of a run folder
(`--phi sasmi/weights/phi.pt`).
`benchmarks/reference_weights.py` retrains them bit for bit.
"""
from __future__ import annotations

from pathlib import Path

from sasmi.errors import SasmiError

HERE = Path(__file__).resolve().parent
FILES = {"phi": "phi.pt", "sasgan": "sasgan.pt", "seabeds": "seabeds.pt"}
INSTEAD = {"phi": "--phi RUN", "sasgan": "--generator RUN", "seabeds": "--floors DIR --real DIR"}


def shipped(name: str) -> Path:
    """The path of a shipped weight file, or a SasmiError saying what to pass instead."""
    path = HERE / FILES[name]
    if not path.is_file():
        raise SasmiError(f"{path}: the shipped {name} weights are missing from this installation; "
                         f"reinstall sasmi, or pass {INSTEAD[name]}")
    return path
