"""Evaluation of image sets against real images, in the φ space of the GAN's autoencoder.

One file per job, in pipeline order (clean-fid style: features, then metrics, then report):
- features.py      images → (N, S, S) in [0, 1] → φ (N, D) float64
- cache.py         the real set's φ kept on disk between evaluations
- metrics.py       FID (± bootstrap, matched-size ratio), KID, precision/recall: pure numpy on (N, D)
- neighbours.py    nearest neighbours and the copying detector
- coverage.py      recall chip by chip: the real chips a set misses
- preservation.py  target preservation on labelled sets (masks + labels.jsonl)
- sweeps.py        pose sweeps through a renderer and a generator
- report.py        markdown, metrics.json and figures (text and plots only)
- config.py        EvalConfig, PreservationConfig, SweepConfig
- evaluate.py      the whole evaluation as one call (what `sasmi evaluate` runs)

    from sasmi.eval import phi_fid
    phi_fid("real_chips/", "translated/")                   # one number, in the shipped φ (phi="runs/ae": your own)

Definitions: docs/evaluate.md.
"""
from sasmi.eval.evaluate import evaluate_folders, phi_fid

__all__ = ["evaluate_folders", "phi_fid"]
