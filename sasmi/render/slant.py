"""Slant-range imaging (`sonar.slant_range = true`): the image's x axis in distance from the track.

A sonar sorts echoes by their travel time, i.e. by slant range R = sqrt((x - x_track)^2 +
(z - altitude)^2), not by ground range x. The render sees the chip from above (ground
range); this module moves every pixel's radiance to the column of its slant range, using
the height of the surface seen through it (a ray cast), so:
- layover: a point above the floor is nearer in slant range than the floor under it, so a
  target's top lands on the floor in front of it and adds to it; the highlight of a
  target's sonar-facing side and top sits on its leading (near-range) edge;
- foreshortening: a slope facing the array spans fewer slant columns than its ground extent
  and is brighter; a slope facing away is stretched and dimmer.

Columns are evenly spaced in slant range between the flat floor's slant ranges at the
chip's near and far ground edges; rows stay along-track. Each pixel's value is split
between the two nearest columns (linear splatting) and every column is divided by what a
flat floor contributes to it, so a flat floor keeps its level and echoes at the same range
add up, as they do in a sonar. Masks and labels follow the same mapping.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sasmi.render.geometry import Geometry


@dataclass(frozen=True)
class SlantMap:
    """Where each ground-range pixel (its visible surface) lands in the slant-range image (chip units)."""
    size: int
    x_track: float
    altitude: float
    near: float  # slant range of the flat floor at the chip's near edge
    far: float  # ... and at its far edge
    u: np.ndarray  # (H, W) float64 slant column of each pixel's surface (pixel centres at integers)
    flat_weight: np.ndarray  # (W,) what a flat floor splats into each slant column
    ground_column: np.ndarray  # (W,) int: the ground column whose flat floor lies at each slant column

    def column(self, x, z):
        """Slant column coordinate of points at ground x and height z (chip units)."""
        return (np.hypot(np.asarray(x) - self.x_track, np.asarray(z) - self.altitude) - self.near) \
            / (self.far - self.near) * self.size - 0.5


def slant_map(g: Geometry, heights: np.ndarray) -> SlantMap:
    """`heights` (H, W): the height in chip units of the surface seen through each pixel centre."""
    n = g.size
    x_track, altitude = float(g.emitter_positions[0, 0]), float(g.emitter_positions[0, 2])
    near, far = float(np.hypot(-1 - x_track, altitude)), float(np.hypot(1 - x_track, altitude))
    centres = (np.arange(n) + 0.5) / n * 2 - 1
    m = SlantMap(n, x_track, altitude, near, far, np.zeros(0), np.zeros(0), np.zeros(0, dtype=np.int64))
    flat_weight = splat(np.ones((1, n)), m.column(centres, 0.0)[None, :])[0]
    slant = near + (np.arange(n) + 0.5) / n * (far - near)
    ground_x = x_track + np.sqrt(np.maximum(slant**2 - altitude**2, 0))
    ground_column = np.clip(np.round((ground_x + 1) / 2 * n - 0.5), 0, n - 1).astype(np.int64)
    return SlantMap(n, x_track, altitude, near, far, u=m.column(centres[None, :], heights),
                    flat_weight=flat_weight, ground_column=ground_column)


def splat(values: np.ndarray, u: np.ndarray) -> np.ndarray:
    """(H, W) values added into their rows at fractional columns u (H, W), linear weights; (H, W) sums."""
    h, w = values.shape
    u = np.broadcast_to(u, values.shape)
    left = np.floor(u).astype(np.int64)
    frac = u - left
    rows = np.arange(h)[:, None] * w
    out = np.zeros(h * w)
    for column, weight in ((left, 1 - frac), (left + 1, frac)):
        inside = (column >= 0) & (column < w)
        out += np.bincount((rows + column)[inside], (values * weight)[inside], minlength=h * w)
    return out.reshape(h, w)


def to_slant(image: np.ndarray, m: SlantMap) -> np.ndarray:
    """(H, W) ground-range radiance -> (H, W) slant-range radiance (a flat floor keeps its level)."""
    return splat(image.astype(np.float64), m.u) / np.maximum(m.flat_weight, 1e-12)[None, :]


def labels_to_slant(visible: np.ndarray, owner: np.ndarray, m: SlantMap) -> tuple[np.ndarray, np.ndarray]:
    """Visible-target and shadowing-target indices (H, W) in slant range.

    A slant pixel shows a target when target surfaces put at least half a flat floor's
    weight into it; which one is the last target pixel nearest to it. Shadow is where the
    flat floor at that slant range is shadowed (shadowed floor points are floor, z ~ 0).
    """
    h, w = visible.shape
    target = splat((visible >= 0).astype(np.float64), m.u)
    nearest = np.full(h * w, -1, dtype=np.int64)
    rows, cols = np.nonzero(visible >= 0)
    u = m.u[rows, cols]
    # the farther neighbour first, so the nearest column is written last and wins
    for column in (np.where(u - np.floor(u) < 0.5, np.floor(u) + 1, np.floor(u)), np.round(u)):
        column = column.astype(np.int64)
        inside = (column >= 0) & (column < w)
        nearest[rows[inside] * w + column[inside]] = visible[rows[inside], cols[inside]]
    seen = np.where(target >= 0.5 * m.flat_weight[None, :], nearest.reshape(h, w), -1)
    shadow = np.where(seen >= 0, -1, owner[:, m.ground_column])
    return seen, shadow
