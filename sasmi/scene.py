"""Scene description: plain frozen dataclasses, loaded from TOML presets in `scenes/`.

No renderer is imported here; both renderers (Mitsuba, POV-Ray) read the same `Scene`.

Coordinates: x is ground range (m), increasing to the right of the image, the sonar
track is off the left edge at x = 0; y is along-track (m), image rows; z is up.
Target positions are given relative to the chip centre.

A preset value may be a plain value or a distribution, `{uniform = [lo, hi]}`,
`{normal = [mean, std]}` or `{choice = [a, b, ...]}`, so one preset describes a family
of scenes; `Preset.sample(seed, index)` draws scene `index` from a generator seeded by
(seed, index) alone, so any scene can be re-made without the ones before it. With a
top-level `targets_per_chip`, the [[targets]] tables are kinds of target drawn by `weight`
(see `TargetKinds`); a [companions] table adds other objects off the chip's centre (see
`Companions`). Value checks and draws live in sasmi/scene_values.py.
"""
from __future__ import annotations

import dataclasses
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from sasmi import limits
from sasmi.errors import SasmiError
from sasmi.scene_values import (check_mesh_file, check_table, check_value, companion_kinds, draw, read_small_file,
                                sample_table, target_kinds)

SHAPES = ("cylinder", "sphere", "cone", "box", "torus", "boulder", "mesh")
BACKSCATTER = ("lambert", "lambert2", "rough")


def _positive(v: float) -> bool:
    return v > 0


def _nonneg(v: float) -> bool:
    return v >= 0


def _unit(v: float) -> bool:
    return 0 <= v <= 1


def _spec(default: Any, check: Callable[[Any], bool] | None = None, allowed: str = "", doc: str = "") -> Any:
    return field(default=default, metadata={"check": check, "allowed": allowed, "doc": doc})


@dataclass(frozen=True)
class Sonar:
    max_range: float = _spec(60.0, _positive, "> 0", "m; the array flies at altitude max_range / 10 unless altitude is set")
    near_range: float = _spec(30.0, _nonneg, ">= 0", "m; ground range of the chip's left edge")
    chip_size: float = _spec(6.0, _positive, "> 0", "m; ground extent of the square chip")
    track_length: float = _spec(20.0, _positive, "> 0", "m; synthetic aperture, centred on the chip")
    emitters: int = _spec(32, _positive, ">= 1", "spot lights evenly spaced along the track")
    cone_angle: float = _spec(30.0, lambda v: 0 < v < 90, "in (0, 90)", "deg; beam half-angle (cutoff)")
    intensity: float = _spec(1.0, _positive, "> 0", "source level, relative to the calibrated exposure")
    altitude: float = _spec(0.0, _nonneg, ">= 0", "m; height of the array above the seafloor; 0 = max_range / 10")
    slant_range: bool = _spec(False, None, "true or false", "image x axis in slant range from the track "
                              "(layover, foreshortening), as a sonar forms images; false: ground range")
    aperture_angle: float = _spec(0.0, lambda v: 0 <= v < 90, "in [0, 90)",
                                  "deg; > 0: beams look broadside with this along-track width, so the synthetic "
                                  "aperture grows with range (track_length is then derived); 0: spots aim at the chip")

    @property
    def array_altitude(self) -> float:
        """m; `altitude`, or max_range / 10 (the paper's geometry) when it is 0."""
        return self.altitude or self.max_range / 10.0


@dataclass(frozen=True)
class Seafloor:
    albedo: float = _spec(0.5, _unit, "in [0, 1]", "Lambertian reflectance of the sediment")
    rms_height: float = _spec(0.01, _nonneg, ">= 0", "m; rms of the power-law rough surface")
    correlation_length: float = _spec(0.5, _positive, "> 0", "m; roll-off scale of the roughness spectrum")
    spectral_exponent: float = _spec(3.5, _positive, "> 0", "power-law exponent of the roughness spectrum")
    ripple_amplitude: float = _spec(0.0, _nonneg, ">= 0", "m; sand-ripple amplitude")
    ripple_wavelength: float = _spec(0.8, _positive, "> 0", "m")
    ripple_direction: float = _spec(0.0, None, "", "deg; direction of the ripple wave vector from +x (range)")
    rocks: int = _spec(0, _nonneg, ">= 0", "number of rock/clutter bumps")
    rock_radius: float = _spec(0.15, _positive, "> 0", "m; size of each bump")
    backscatter: str = _spec("lambert", lambda v: v in BACKSCATTER, "one of " + ", ".join(BACKSCATTER),
                             "scattering law: lambert (cos of incidence, as today), lambert2 (cos^2, Lambert's law), "
                             "rough (cos^0.5, nearly even: rock and rubble)")
    patchiness: float = _spec(0.0, lambda v: 0 <= v <= 2, "in [0, 2]", "std / mean of the sediment's backscatter "
                              "strength over the floor (a gamma texture under the speckle: K-distributed clutter); "
                              "0 = uniform; above 2 most of the floor renders black")
    patch_size: float = _spec(1.0, _positive, "> 0", "m; width (FWHM) of the patches of stronger and weaker backscatter")


@dataclass(frozen=True)
class Target:
    shape: str = _spec("cylinder", lambda v: v in SHAPES, "one of " + ", ".join(SHAPES))
    x: float = _spec(0.0, None, "", "m from the chip centre along range")
    y: float = _spec(0.0, None, "", "m from the chip centre along track")
    yaw: float = _spec(0.0, None, "", "deg; axis angle from +x (range) towards +y (along-track)")
    burial: float = _spec(0.0, _nonneg, ">= 0", "m of the target's height below the local seafloor")
    length: float = _spec(2.0, _positive, "> 0", "m; cylinder length, cone height, box or boulder length (along its axis)")
    radius: float = _spec(0.3, _positive, "> 0", "m; cylinder/sphere radius, cone base radius, torus major radius "
                          "(ring centre to tube centre)")
    radius_top: float = _spec(0.1, _nonneg, ">= 0", "m; top radius of the truncated cone")
    width: float = _spec(1.0, _positive, "> 0", "m; box or boulder width (across its axis)")
    height: float = _spec(0.5, _positive, "> 0", "m; box or boulder height")
    lumpiness: float = _spec(0.3, lambda v: 0 <= v < 0.9, "in [0, 0.9)", "boulder: how far its surface strays from "
                             "a smooth ellipsoid: its largest lump as a share of its radius (the default preset: 0.4-0.85)")
    tube_radius: float = _spec(0.15, _positive, "> 0", "m; torus tube radius (a tyre lying flat: its height is twice this)")
    mesh: str = _spec("", None, "", "OBJ/STL/PLY path (shape = 'mesh'), relative to the preset")
    scale: float = _spec(1.0, _positive, "> 0", "scale applied to a mesh file")
    albedo: float = _spec(0.9, _unit, "in [0, 1]")
    backscatter: str = _spec("lambert", lambda v: v in BACKSCATTER, "one of " + ", ".join(BACKSCATTER),
                             "scattering law, as seafloor.backscatter: rough keeps a boulder's top bright at low grazing")


@dataclass(frozen=True)
class Post:
    gain: float = _spec(0.45, _positive, "> 0",
                        "gray level of a flat albedo-1 seafloor at the chip centre lit by the array at intensity 1")
    speckle_looks: float = _spec(0.0, _nonneg, ">= 0", "L of gamma-distributed multiplicative speckle; 0 = off")
    noise_std: float = _spec(0.0, _nonneg, ">= 0", "std of additive Gaussian noise in gray levels (0..1)")
    tvg: bool = _spec(True, None, "true or false",
                      "time-varying gain: divide out the flat-floor spreading and grazing loss, as sonars do")
    tvg_strength: float = _spec(1.0, _unit, "in [0, 1]",
                                "share of the TVG (an exponent): 1 evens out a flat floor, below 1 a range fall-off remains")
    noise_floor: float = _spec(0.0, _nonneg, ">= 0",
                               "gray level of the background under every echo (reverberation, ambient noise); "
                               "speckled with it, it is the mean level of acoustic shadows")
    speckle_cell_range: float = _spec(0.0, _nonneg, ">= 0", "m; resolution cell along range; speckle is correlated "
                                      "over it (0 = independent per pixel)")
    speckle_cell_track: float = _spec(0.0, _nonneg, ">= 0", "m; resolution cell along track (0 = independent per pixel)")


@dataclass(frozen=True)
class TargetGrid:
    """Targets on a regular grid over the chip (the paper's target field)."""
    spacing: float = _spec(5.0, _positive, "> 0", "m between grid points")
    jitter: float = _spec(0.0, _nonneg, ">= 0", "m; uniform random offset of each target")


@dataclass(frozen=True)
class Scene:
    sonar: Sonar = Sonar()
    seafloor: Seafloor = Seafloor()
    targets: tuple[Target, ...] = ()
    post: Post = Post()
    seed: int = 0  # drives the heightfield, rocks, speckle and the sampler

    def validate(self, names: tuple[str, ...] = ()) -> "Scene":
        """Cross-field checks; raises SasmiError naming the field. `names[i]`: the preset table of target i
        (targets drawn by kind come from the table of their kind); default targets[i]."""
        s = self.sonar
        if s.near_range + s.chip_size > s.max_range:
            raise SasmiError(f"sonar.near_range: chip far edge {s.near_range + s.chip_size:g} m exceeds "
                             f"sonar.max_range {s.max_range:g} m")
        f = self.seafloor
        relief = 4 * f.rms_height + f.ripple_amplitude + (1.4 * f.rock_radius if f.rocks else 0.0)
        altitude = f"{s.array_altitude:g} m" + ("" if s.altitude else " (sonar.max_range / 10)")
        if relief >= s.array_altitude:  # the floor would hide the array: a black chip, not an error, otherwise
            raise SasmiError(f"seafloor: relief up to {relief:g} m (4 rms_height + ripple_amplitude + 1.4 rock_radius) "
                             f"reaches the array at altitude {altitude}")
        half = s.chip_size / 2
        for i, t in enumerate(self.targets):
            where = names[i] if i < len(names) else f"targets[{i}]"
            top = (target_height(t) or 0.0) - t.burial
            if top >= s.array_altitude:
                raise SasmiError(f"{where}: rises {top:g} m above the floor, to the array at altitude {altitude}")
            if not (-half < t.x < half):
                raise SasmiError(f"{where}.x: {t.x:g} m lies outside the chip (allowed: -{half:g} < x < {half:g})")
            if not (-half < t.y < half):
                raise SasmiError(f"{where}.y: {t.y:g} m lies outside the chip (allowed: -{half:g} < y < {half:g})")
            if t.shape == "mesh" and not t.mesh:
                raise SasmiError(f"{where}.mesh: a file path is required when shape = 'mesh'")
            if t.shape == "mesh":
                check_mesh_file(Path(t.mesh), f"{where}.mesh")
            height = target_height(t)
            if height is not None and t.burial >= height:
                raise SasmiError(f"{where}.burial: {t.burial:g} m buries the whole target "
                                 f"(allowed: 0 <= burial < height {height:g} m)")
            if t.shape == "cone" and t.radius_top > t.radius:
                raise SasmiError(f"{where}.radius_top: {t.radius_top:g} exceeds radius {t.radius:g}")
            if t.shape == "torus" and t.tube_radius >= t.radius:
                raise SasmiError(f"{where}.tube_radius: {t.tube_radius:g} m closes the ring "
                                 f"(allowed: < radius {t.radius:g} m)")
        return self


def target_height(t: Target) -> float | None:
    """Height of the target above its lowest point; None for meshes (known only once loaded)."""
    if t.shape in ("cylinder", "sphere"):
        return 2 * t.radius
    if t.shape == "cone":
        return t.length
    if t.shape in ("box", "boulder"):
        return t.height
    if t.shape == "torus":
        return 2 * t.tube_radius
    return None


# ---------------------------------------------------------------------------------------
# Presets: TOML with distributions
# ---------------------------------------------------------------------------------------

@dataclass(frozen=True)
class TargetKinds:
    """Targets drawn per chip: with `targets_per_chip` set, every [[targets]] table is a kind of target
    (its own shapes and size ranges), and each of a chip's targets picks a kind with probability
    weight / (sum of weights). Without it, every table is one target of every chip."""
    targets_per_chip: int = _spec(1, _nonneg, ">= 0", "targets per chip, each drawn from the [[targets]] tables "
                                  "by their weight")
    weight: float = _spec(1.0, _nonneg, ">= 0", "a [[targets]] table's share of the draws (with targets_per_chip)")


@dataclass(frozen=True)
class Companions:
    """Other objects in view beside a chip's target(s), as real chips show them (rocks, debris, another
    mine): the [[companions.kinds]] tables are kinds like [[targets]] ones (weight, shape, sizes), and each
    companion lies at random over the chip, `clearance` from every other object and half of it from the
    edges. They are drawn from their own random stream, so adding them changes no other draw of a scene."""
    share: float = _spec(0.0, _unit, "in [0, 1]", "share of chips that have companions")
    most: int = _spec(1, lambda v: 1 <= v <= 16, "in [1, 16]", "companions in such a chip: 1 to `most`, evenly")
    clearance: float = _spec(4.0, _positive, "> 0", "m from a companion's centre to every other object's")


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
            if name in raw:
                check_table(section, raw[name], name)
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
            kind = sample_table(Target, t, rng, where)
            dataclasses.replace(scene, targets=(kind,)).validate(names=(where,))
        return preset

    def resolve_mesh(self, mesh: str) -> Path:
        p = Path(mesh).expanduser()
        if not p.is_absolute() and self.path is not None:
            p = self.path.parent / p
        return p

    def sample(self, seed: int, index: int) -> Scene:
        rng = np.random.default_rng([seed, index])
        sonar = sample_table(Sonar, self.raw.get("sonar", {}), rng, "sonar")
        seafloor = sample_table(Seafloor, self.raw.get("seafloor", {}), rng, "seafloor")
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
        targets = [dataclasses.replace(t, mesh=str(self.resolve_mesh(t.mesh))) if t.shape == "mesh" and t.mesh else t
                   for t in targets]
        scene_seed = int(rng.integers(2**31 - 1))
        return Scene(sonar=sonar, seafloor=seafloor, targets=tuple(targets), post=post, seed=scene_seed
                     ).validate(names)

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
                    companions.append(sample_table(Target, tables[k], rng, f"companions.kinds[{k}]", x=x, y=y))
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
    """The presets: package data `sasmi.scenes` (scenes/ at the top of the repository)."""
    try:
        from sasmi import scenes
    except ImportError:  # a source tree used without installing it
        return Path(__file__).resolve().parent.parent / "scenes"
    return Path(scenes.__file__).resolve().parent


SCENES = _shipped_folder()


def shipped_presets() -> list[str]:
    return sorted(p.stem for p in SCENES.glob("*.toml"))


def _find_preset(path: Path) -> Path:
    """`path` itself, or a shipped preset by name ("cylinder_chip" -> scenes/cylinder_chip.toml)."""
    if path.exists() or len(path.parts) != 1:
        return path
    shipped = SCENES / (path.name if path.suffix == ".toml" else path.name + ".toml")
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


def scene_to_dict(scene: Scene) -> dict:
    return dataclasses.asdict(scene)

