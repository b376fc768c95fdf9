"""Presets: TOML files in `scenes/` that describe a family of scenes (sasmi/scene/model.py's dataclasses).

A preset value may be a plain value or a distribution, `{uniform = [lo, hi]}`,
`{normal = [mean, std]}` or `{choice = [a, b, ...]}`, so one preset describes a family
of scenes; `Preset.sample(seed, index)` draws scene `index` from a generator seeded by
(seed, index) alone, so any scene can be re-made without the ones before it. With a
top-level `targets_per_chip`, the [[targets]] tables are kinds of target drawn by `weight`
(see `TargetKinds`); [[seafloor]] tables in place of one [seafloor] are kinds of seabed, one drawn per
chip by `weight` (see `SeafloorKinds`); a [companions] table adds other objects off the chip's centre (see
`Companions`). Value checks and draws live in sasmi/scene/values.py.
"""
from __future__ import annotations

import dataclasses
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sasmi import limits
from sasmi.errors import SasmiError
from sasmi.scene.model import Post, Scene, Seafloor, Sonar, Target, TargetGrid, nonneg, positive, spec, unit
from sasmi.scene.values import (check_table, check_value, companion_kinds, draw, read_small_file, sample_table,
                                seafloor_kinds, target_kinds)


@dataclass(frozen=True)
class TargetKinds:
    """Targets drawn per chip: with `targets_per_chip` set, every [[targets]] table is a kind of target
    (its own shapes and size ranges), and each of a chip's targets picks a kind with probability
    weight / (sum of weights). Without it, every table is one target of every chip."""
    targets_per_chip: int = spec(1, nonneg, ">= 0", "targets per chip, each drawn from the [[targets]] tables "
                                 "by their weight")
    weight: float = spec(1.0, nonneg, ">= 0", "a [[targets]] table's share of the draws (with targets_per_chip)")


@dataclass(frozen=True)
class SeafloorKinds:
    """Seabeds of several kinds in one preset: real surveys cross sand waves, flat mud and patches of other
    sediments, and a chip shows one of them. Each [[seafloor]] table is a kind (every [seafloor] field, its
    own values and ranges), and each chip's floor is drawn from one kind picked with probability
    weight / (sum of weights). A single [seafloor] table is the one kind of every chip."""
    weight: float = spec(1.0, nonneg, ">= 0", "a [[seafloor]] table's share of the chips")


@dataclass(frozen=True)
class Companions:
    """Other objects in view beside a chip's target(s), as real chips show them (rocks, debris, another
    mine): the [[companions.kinds]] tables are kinds like [[targets]] ones (weight, shape, sizes), and each
    companion lies at random over the chip, `clearance` from every other object and half of it from the
    edges. They are drawn from their own random stream, so adding them changes no other draw of a scene."""
    share: float = spec(0.0, unit, "in [0, 1]", "share of chips that have companions")
    most: int = spec(1, lambda v: 1 <= v <= 16, "in [1, 16]", "companions in such a chip: 1 to `most`, evenly")
    clearance: float = spec(4.0, positive, "> 0", "m from a companion's centre to every other object's")


PLACEMENT_TRIES = 20  # random places tried for a companion before the chip goes without it
SECTIONS = {"sonar": Sonar, "seafloor": Seafloor, "post": Post}
TOP_KEYS = set(SECTIONS) | {"targets", "target_grid", "targets_per_chip", "companions", "description"}


@dataclass(frozen=True)
class Preset:
    """A validated preset: a family of scenes. `sample(seed, index)` returns one `Scene`."""
    raw: dict
    path: Path | None = None

    @classmethod
    def from_dict(cls, raw: dict, path: Path | None = None) -> "Preset":
        for key in raw:
            if key not in TOP_KEYS:
                raise SasmiError(f"{key}: unknown section (allowed: {', '.join(sorted(TOP_KEYS))})")
        for name, section in SECTIONS.items():
            if name in raw and name != "seafloor":
                check_table(section, raw[name], name)
        floors, floor_weights = seafloor_kinds(raw, SeafloorKinds)
        for i, floor in enumerate(floors):
            check_table(Seafloor, floor, "seafloor" if floor_weights is None else f"seafloor[{i}]")
        if not isinstance(raw.get("targets", []), list):
            raise SasmiError("targets: expected an array of tables ([[targets]])")
        targets, weights = target_kinds(raw, TargetKinds)
        if len(targets) > limits.MAX_TARGETS:
            raise SasmiError(f"targets: {len(targets)} targets (allowed: <= {limits.MAX_TARGETS})")
        for i, t in enumerate(targets):
            check_table(Target, t, f"targets[{i}]")
        if "description" in raw and not isinstance(raw["description"], str):
            raise SasmiError(f"description: expected a string, got {type(raw['description']).__name__}")
        if "target_grid" in raw:
            if not isinstance(raw["target_grid"], dict):
                raise SasmiError(f"target_grid: expected a table, got {type(raw['target_grid']).__name__}")
            grid = dict(raw["target_grid"])
            target = grid.pop("target", {})
            check_table(TargetGrid, grid, "target_grid")
            check_table(Target, target, "target_grid.target", skip=("x", "y"))
        kinds = {f"targets[{i}]": t for i, t in enumerate(targets)} if weights is not None else {}
        if "companions" in raw:
            _, companions, _ = companion_kinds(raw["companions"], Companions, TargetKinds, Target)
            kinds |= {f"companions.kinds[{i}]": t for i, t in enumerate(companions)}
        preset = cls(raw=raw, path=path)
        scene = preset.sample(0, 0)  # cross-field checks on one draw, so a broken preset fails at load
        rng = np.random.default_rng(0)  # and on one draw of every kind, which one chip may not pick
        for where, t in kinds.items():
            kind = preset.with_mesh_resolved(sample_table(Target, t, rng, where))
            dataclasses.replace(scene, targets=(kind,)).validate(names=(where,))
        if floor_weights is not None:
            for i, floor in enumerate(floors):
                where = f"seafloor[{i}]"
                dataclasses.replace(scene, seafloor=sample_table(Seafloor, floor, rng, where)).validate(floor=where)
        return preset

    def with_mesh_resolved(self, t: Target) -> Target:
        """A mesh target with its file found relative to the preset's folder; any other target as it is."""
        return dataclasses.replace(t, mesh=str(self.resolve_mesh(t.mesh))) if t.shape == "mesh" and t.mesh else t

    def resolve_mesh(self, mesh: str) -> Path:
        p = Path(mesh).expanduser()
        if not p.is_absolute() and self.path is not None:
            p = self.path.parent / p
        return p

    def sample(self, seed: int, index: int) -> Scene:
        rng = np.random.default_rng([seed, index])
        sonar = sample_table(Sonar, self.raw.get("sonar", {}), rng, "sonar")
        floors, floor_weights = seafloor_kinds(self.raw, SeafloorKinds)
        # one [seafloor] table draws nothing here, so its scenes are drawn as they were before kinds
        floor = 0 if floor_weights is None else int(rng.choice(len(floors), p=floor_weights))
        floor_name = "seafloor" if floor_weights is None else f"seafloor[{floor}]"
        seafloor = sample_table(Seafloor, floors[floor], rng, floor_name)
        post = sample_table(Post, self.raw.get("post", {}), rng, "post")
        tables, weights = target_kinds(self.raw, TargetKinds)
        if weights is None:
            picks = list(range(len(tables)))
        else:
            drawn = draw(self.raw["targets_per_chip"], rng)
            count = check_value(TargetKinds, "targets_per_chip", int(round(drawn)), "targets_per_chip")
            if count > limits.MAX_TARGETS:
                raise SasmiError(f"targets_per_chip: {count} (allowed: <= {limits.MAX_TARGETS})")
            picks = [int(k) for k in rng.choice(len(tables), size=count, p=weights)]
        targets = [sample_table(Target, tables[k], rng, f"targets[{k}]") for k in picks]
        names = tuple(f"targets[{k}]" for k in picks)
        if "target_grid" in self.raw:
            targets += self._grid_targets(sonar, rng, len(targets))
            names += tuple(f"targets[{k}]" for k in range(len(names), len(targets)))
        if "companions" in self.raw:
            companions, kinds = self._companions(sonar, targets, np.random.default_rng([seed, index, 1]))
            targets, names = targets + companions, names + kinds
        targets = [self.with_mesh_resolved(t) for t in targets]
        scene_seed = int(rng.integers(2**31 - 1))
        return Scene(sonar=sonar, seafloor=seafloor, targets=tuple(targets), post=post, seed=scene_seed
                     ).validate(names, floor=floor_name)

    def _companions(self, sonar: Sonar, targets: list[Target], rng: np.random.Generator
                    ) -> tuple[list[Target], tuple[str, ...]]:
        """This chip's companions and the names of their kinds, placed clear of `targets` and of each other."""
        settings, tables, weights = companion_kinds(self.raw["companions"], Companions, TargetKinds, Target)
        c = sample_table(Companions, settings, rng, "companions")
        half = (sonar.chip_size - c.clearance) / 2
        if half <= 0:
            raise SasmiError(f"companions.clearance: {c.clearance:g} m leaves no room on a {sonar.chip_size:g} m chip "
                             f"(allowed: < sonar.chip_size)")
        if rng.random() >= c.share:
            return [], ()
        taken = [(t.x, t.y) for t in targets]
        companions, names = [], ()
        for _ in range(int(rng.integers(1, c.most + 1))):
            k = int(rng.choice(len(tables), p=weights))
            for _try in range(PLACEMENT_TRIES):
                x, y = (float(v) for v in rng.uniform(-half, half, size=2))
                if all(math.hypot(x - tx, y - ty) >= c.clearance for tx, ty in taken):
                    taken.append((x, y))
                    companions.append(sample_table(Target, tables[k], rng, f"companions.kinds[{k}]", x=x, y=y,
                                                       role="companion"))
                    names += (f"companions.kinds[{k}]",)
                    break
        return companions, names

    def _grid_targets(self, sonar: Sonar, rng: np.random.Generator, first: int) -> list[Target]:
        grid_raw = dict(self.raw["target_grid"])
        target_raw = grid_raw.pop("target", {})
        grid = sample_table(TargetGrid, grid_raw, rng, "target_grid")
        half = sonar.chip_size / 2
        count = int(math.floor(sonar.chip_size / grid.spacing))
        if count < 1:
            raise SasmiError(f"target_grid.spacing: {grid.spacing:g} m leaves no room on a {sonar.chip_size:g} m chip")
        if first + count * count > limits.MAX_TARGETS:  # checked before any target is made: 1 mm is 10^9 of them
            side = math.isqrt(max(limits.MAX_TARGETS - first, 0))
            raise SasmiError(f"target_grid.spacing: {grid.spacing:g} m on a {sonar.chip_size:g} m chip makes "
                             f"{count}² targets (allowed: <= {limits.MAX_TARGETS} targets in a scene, here a spacing "
                             f">= {sonar.chip_size / max(side, 1):g} m)")
        centres = (np.arange(count) + 0.5) * grid.spacing - count * grid.spacing / 2
        targets = []
        for row, y in enumerate(centres):
            for col, x in enumerate(centres):
                k = first + row * count + col
                jx, jy = rng.uniform(-grid.jitter, grid.jitter, size=2)
                xy = {"x": float(np.clip(x + jx, -half * 0.98, half * 0.98)),
                      "y": float(np.clip(y + jy, -half * 0.98, half * 0.98))}
                targets.append(sample_table(Target, target_raw, rng, f"targets[{k}]", **xy))
        return targets


def _shipped_folder() -> Path:
    """The presets: package data `sasmi.presets` (scenes/ at the top of the repository)."""
    try:
        from sasmi import presets
    except ImportError:  # a source tree used without installing it
        return Path(__file__).resolve().parents[2] / "scenes"
    return Path(presets.__file__).resolve().parent


PRESETS = _shipped_folder()


def shipped_presets() -> list[str]:
    return sorted(p.stem for p in PRESETS.glob("*.toml"))


def _find_preset(path: Path) -> Path:
    """`path` itself, or a shipped preset by name ("cylinder_chip" -> scenes/cylinder_chip.toml)."""
    if path.exists() or len(path.parts) != 1:
        return path
    shipped = PRESETS / (path.name if path.suffix == ".toml" else path.name + ".toml")
    if shipped.is_file():
        return shipped
    names = ", ".join(shipped_presets())
    raise SasmiError(f"{path}: preset not found (a TOML file, or a shipped preset: {names})")


def load_preset(path: str | Path) -> Preset:
    """Read and validate a TOML preset (a path, or the name of a shipped one); errors name the file or field."""
    path = _find_preset(Path(path))
    data = read_small_file(path, limits.PRESET_MAX_BYTES, "preset")
    try:
        raw = tomllib.loads(data.decode("utf-8"))
    except UnicodeDecodeError as e:
        raise SasmiError(f"{path}: not a text file ({e.reason} at byte {e.start})") from None
    except tomllib.TOMLDecodeError as e:
        raise SasmiError(f"{path}: not valid TOML ({e})") from None
    except RecursionError:
        raise SasmiError(f"{path}: not valid TOML (nested too deeply)") from None
    return Preset.from_dict(raw, path=path)
