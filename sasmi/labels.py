"""Typed label records of a render set: one writer (`ChipLabel.to_json`), one reader (`read_labels`).

On disk: `labels/NNNNNN.json`, one per chip and written last (it marks the chip
complete), and `labels.jsonl`, all of them in index order. A record holds the sampled scene (`sonar`, `seafloor`, `post`, `seed`: the
scene's own seed) and per target its sampled parameters plus what the render measured.
Pixel coordinates are (col, row) = (x, y) of the image, boxes (col0, row0, col1, row1)
with the end exclusive.
"""
from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from sasmi.errors import SasmiError

Box = tuple[float, float, float, float]

# keys of a target record that the render measured; every other key is a sampled parameter
_MEASURED = ("pixel_centre", "bbox", "shadow_bbox", "visible_pixels", "shadow_pixels", "geometry")


def _box(value: Any) -> Box | None:
    return None if value is None else tuple(float(v) for v in value)


def _finite(value: Any, where: str) -> Any:
    """JSON has no NaN or Infinity: refuse them instead of writing a file other tools cannot read."""
    if isinstance(value, float) and not math.isfinite(value):
        raise SasmiError(f"{where}: {value} is not a finite number")
    if isinstance(value, dict):
        return {k: _finite(v, f"{where}.{k}") for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v, f"{where}[{i}]") for i, v in enumerate(value)]
    return value


@dataclass(frozen=True)
class TargetLabel:
    """One target: its sampled parameters and where the render put it."""
    params: dict  # shape, x, y (m from the chip centre), yaw (deg), burial (m), sizes, albedo, ...
    pixel_centre: tuple[float, float]  # (col, row) of the target's centre, px
    bbox: Box | None  # visible target pixels; None when the camera sees none of it
    shadow_bbox: Box | None  # its acoustic shadow; None when it casts none on the chip
    visible_pixels: int = 0
    shadow_pixels: int = 0
    # altitude, ground_range, slant_range (m), grazing_angle (deg), along_track (m), heading (deg = yaw):
    # what ATR papers stratify by
    geometry: dict = field(default_factory=dict)

    @property
    def shape(self) -> str:
        return str(self.params.get("shape", ""))

    @property
    def role(self) -> str:
        """"target", or "companion": another object in view (sasmi.scene.model.Target.role; a record without it: target)."""
        return str(self.params.get("role", "target"))

    @property
    def category(self) -> str:
        """The class name an ATR model learns: the shape, or a mesh file's stem."""
        if self.shape == "mesh" and self.params.get("mesh"):
            return Path(str(self.params["mesh"])).stem
        return self.shape

    def scaled(self, scale: float) -> "TargetLabel":
        """The same label in the pixels of an image `scale` times as large (pixel centres stay centres)."""
        def box(b: Box | None) -> Box | None:
            return None if b is None else tuple(v * scale for v in b)

        col, row = self.pixel_centre
        return replace(self, pixel_centre=((col + 0.5) * scale - 0.5, (row + 0.5) * scale - 0.5),
                       bbox=box(self.bbox), shadow_bbox=box(self.shadow_bbox))

    def to_json(self) -> dict:
        return {**self.params, "pixel_centre": list(self.pixel_centre),
                "bbox": None if self.bbox is None else [int(v) if float(v).is_integer() else v for v in self.bbox],
                "shadow_bbox": None if self.shadow_bbox is None
                else [int(v) if float(v).is_integer() else v for v in self.shadow_bbox],
                "visible_pixels": self.visible_pixels, "shadow_pixels": self.shadow_pixels,
                **({"geometry": self.geometry} if self.geometry else {})}

    @classmethod
    def from_json(cls, d: dict) -> "TargetLabel":
        return cls(params={k: v for k, v in d.items() if k not in _MEASURED},
                   pixel_centre=tuple(float(v) for v in d["pixel_centre"]),
                   bbox=_box(d.get("bbox")), shadow_bbox=_box(d.get("shadow_bbox")),
                   visible_pixels=int(d.get("visible_pixels", 0)), shadow_pixels=int(d.get("shadow_pixels", 0)),
                   geometry=dict(d.get("geometry") or {}))


@dataclass(frozen=True)
class ChipLabel:
    """Everything known about one chip of a render set."""
    index: int
    size: int  # image side, px
    scene: dict  # sonar, seafloor, post (sampled parameters) and seed (the scene's own)
    targets: tuple[TargetLabel, ...] = ()
    image: str = ""  # path of the image, relative to the render set
    mask: str = ""  # path of the class mask, relative to the render set
    extra: dict = field(default_factory=dict)  # keys this version does not know, kept on rewrite
    # labelled clutter (rocks): kind, pixel_centre (col, row), radius (px), bbox (col0, row0, col1, row1),
    # x, y, radius_m (m); written only when there is some, so a record without it reads as no clutter
    clutter: tuple[dict, ...] = ()

    def to_json(self) -> dict:
        record = {"index": self.index, "image": self.image, "mask": self.mask, **self.scene,
                  "targets": [t.to_json() for t in self.targets], "size": self.size,
                  **({"clutter": [dict(c) for c in self.clutter]} if self.clutter else {}), **self.extra}
        return _finite(record, f"labels[{self.index}]")

    def dumps(self) -> str:
        return json.dumps(self.to_json(), allow_nan=False)

    @classmethod
    def from_json(cls, d: dict) -> "ChipLabel":
        scene_keys = ("sonar", "seafloor", "post", "seed")
        known = ("index", "image", "mask", "targets", "size", "clutter", *scene_keys)
        return cls(index=int(d["index"]), size=int(d["size"]),
                   scene={k: d[k] for k in scene_keys if k in d},
                   targets=tuple(TargetLabel.from_json(t) for t in d.get("targets", ())),
                   image=str(d.get("image", "")), mask=str(d.get("mask", "")),
                   clutter=tuple(dict(c) for c in d.get("clutter", ())),
                   extra={k: v for k, v in d.items() if k not in known})


BUILTIN_CATEGORIES = ("cylinder", "sphere", "cone", "box", "torus", "boulder")


def categories_of(labels: list[ChipLabel], preset: dict | None = None) -> list[str]:
    """Class names in id order (id = position + 1; 0 is the background): built-in shapes first, then meshes.

    With the preset's raw tables, every mesh it can draw counts, drawn in these chips or not: two sets
    of one preset then give a mesh the same id, however few chips each holds.
    """
    found = {t.category for label in labels for t in label.targets} | (_mesh_stems(preset) if preset else set())
    return [c for c in BUILTIN_CATEGORIES] + sorted(found - set(BUILTIN_CATEGORIES))


def _mesh_stems(table: Any) -> set[str]:
    """Stems of every `mesh` anywhere in a preset's raw tables: a path, or the paths of a {choice = [...]}."""
    if isinstance(table, list):
        return set().union(*map(_mesh_stems, table))
    if not isinstance(table, dict):
        return set()
    stems = set()
    for key, value in table.items():
        if key != "mesh":
            stems |= _mesh_stems(value)
        elif isinstance(value, str):
            stems.add(Path(value).stem)
        elif isinstance(value, dict):  # a distribution: its one entry lists the choices
            stems |= {Path(v).stem for values in value.values() if isinstance(values, list)
                      for v in values if isinstance(v, str)}
    return stems - {""}


def target_geometry(sonar: dict, x: float, y: float) -> dict:
    """What ATR papers stratify by, for a target at (x, y) m from the chip centre.

    Ground range is measured from the track; the array flies at `sonar.altitude` (or
    max_range / 10 when a preset leaves it unset).
    """
    altitude = sonar.get("altitude") or sonar["max_range"] / 10.0
    ground = sonar["near_range"] + sonar["chip_size"] / 2.0 + x
    slant = math.hypot(ground, altitude)
    return {"altitude": altitude, "ground_range": ground, "slant_range": slant,
            "grazing_angle": math.degrees(math.atan2(altitude, ground)), "along_track": y}


def has_labels(folder: str | os.PathLike) -> bool:
    """True for a render set (or its translation): masks/ and labels.jsonl beside the images."""
    folder = Path(folder)
    return (folder / "masks").is_dir() and (folder / "labels.jsonl").is_file()


def read_labels(folder: str | os.PathLike) -> list[ChipLabel]:
    """Every record of FOLDER/labels.jsonl in file order; a malformed one is a SasmiError naming its line."""
    path = Path(folder) / "labels.jsonl"
    try:
        lines = path.read_text().splitlines()
    except OSError as e:
        raise SasmiError(f"{path}: cannot read labels ({e.strerror or e})") from None
    records = []
    for n, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        try:
            records.append(ChipLabel.from_json(json.loads(line)))
        except json.JSONDecodeError as e:
            raise SasmiError(f"{path}:{n}: not JSON ({e.msg})") from None
        except (KeyError, TypeError, ValueError) as e:
            raise SasmiError(f"{path}:{n}: not a chip label (missing or wrong {e})") from None
    return records


def labels_by_index(folder: str | os.PathLike) -> dict[int, ChipLabel]:
    return {label.index: label for label in read_labels(folder)}
