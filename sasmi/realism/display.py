"""A sonar display's top: its brightest gray levels bent under a ceiling.

A real chip's display bends its brightest levels under a ceiling: the shared target chips' brightest
pixel lies at 0.89-0.95, alone, and none has a flat white patch. A seabed times a speckle, or a
rendered highlight, has no ceiling and clips to white in clusters, which a small classifier sees;
`bent` gives it a display's top.
"""
from __future__ import annotations

import numpy as np

# where the bend starts, as a fraction of the ceiling. On the shared train targets' floors the 99.9th percentile
# is 0.73 (median) and the brightest pixel 0.90; floors drawn from them and bent from 0.6 of their speckle chip's
# brightest level, 0.73 and 0.85 (from 0.8: 0.80 and 0.89; unbent: 0.82 and 1, clipped)
KNEE = 0.6


def bent(value: np.ndarray, ceiling: float) -> np.ndarray:
    """`value` unchanged up to KNEE × ceiling and above it bent smoothly (slope 1 at the knee) towards `ceiling`,
    which it never reaches; an infinite ceiling bends nothing."""
    if not np.isfinite(ceiling):
        return value
    if ceiling <= 0.0:  # a black chip: nothing above its black
        return np.minimum(value, 0.0)
    knee = KNEE * ceiling
    over = np.maximum(value - knee, 0.0)
    return np.where(value > knee, knee - (ceiling - knee) * np.expm1(-over / (ceiling - knee)), value)
