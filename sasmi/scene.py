"""Scene description: plain frozen dataclasses, loaded from TOML presets in `scenes/`.

No renderer is imported here; both renderers (Mitsuba, POV-Ray) read the same `Scene`.

Coordinates: x is ground range (m), increasing to the right of the image, the sonar
track is off the left edge at x = 0; y is along-track (m), image rows; z is up.
Target positions are given relative to the chip centre.

A preset value may be a plain value or a distribution, `{uniform = [lo, hi]}`,
`{normal = [mean, std]}` or `{choice = [a, b, ...]}`, so one preset describes a family
of scenes; `Preset.sample(seed, index)` draws scene `index` from a generator seeded by
(seed, index) alone, so any scene can be re-made without the ones before it.
"""
from __future__ import annotations

import dataclasses
import math
import stat
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from sasmi import limits
from sasmi.errors import SasmiError

SHAPES = ("cylinder", "sphere", "cone", "mesh")
BACKSCATTER = ("lambert", "lambert2")


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
                             "scattering law: lambert (cos of incidence, as today), lambert2 (cos^2, Lambert's law)")


@dataclass(frozen=True)
class Target:
    shape: str = _spec("cylinder", lambda v: v in SHAPES, "one of " + ", ".join(SHAPES))
    x: float = _spec(0.0, None, "", "m from the chip centre along range")
    y: float = _spec(0.0, None, "", "m from the chip centre along track")
    yaw: float = _spec(0.0, None, "", "deg; axis angle from +x (range) towards +y (along-track)")
    burial: float = _spec(0.0, _nonneg, ">= 0", "m of the target's height below the local seafloor")
    length: float = _spec(2.0, _positive, "> 0", "m; cylinder length, cone height")
    radius: float = _spec(0.3, _positive, "> 0", "m; cylinder/sphere radius, cone base radius")
    radius_top: float = _spec(0.1, _nonneg, ">= 0", "m; top radius of the truncated cone")
    mesh: str = _spec("", None, "", "OBJ/STL/PLY path (shape = 'mesh'), relative to the preset")
    scale: float = _spec(1.0, _positive, "> 0", "scale applied to a mesh file")
    albedo: float = _spec(0.9, _unit, "in [0, 1]")


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

    def validate(self) -> "Scene":
        """Cross-field checks; raises SasmiError naming the field."""
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
            top = (target_height(t) or 0.0) - t.burial
            if top >= s.array_altitude:
                raise SasmiError(f"targets[{i}]: rises {top:g} m above the floor, to the array at altitude {altitude}")
            if not (-half < t.x < half):
                raise SasmiError(f"targets[{i}].x: {t.x:g} m lies outside the chip (allowed: -{half:g} < x < {half:g})")
            if not (-half < t.y < half):
                raise SasmiError(f"targets[{i}].y: {t.y:g} m lies outside the chip (allowed: -{half:g} < y < {half:g})")
            if t.shape == "mesh" and not t.mesh:
                raise SasmiError(f"targets[{i}].mesh: a file path is required when shape = 'mesh'")
            if t.shape == "mesh":
                _check_mesh_file(Path(t.mesh), f"targets[{i}].mesh")
            height = target_height(t)
            if height is not None and t.burial >= height:
                raise SasmiError(f"targets[{i}].burial: {t.burial:g} m buries the whole target "
                                 f"(allowed: 0 <= burial < height {height:g} m)")
            if t.shape == "cone" and t.radius_top > t.radius:
                raise SasmiError(f"targets[{i}].radius_top: {t.radius_top:g} exceeds radius {t.radius:g}")
        return self


def _check_mesh_file(path: Path, where: str) -> None:
    """A mesh must be a regular file of bounded size: trimesh would read /dev/zero for ever."""
    try:
        st = path.stat()
    except (OSError, ValueError):  # ValueError: a NUL character in the path
        raise SasmiError(f"{where}: {str(path)!r}: mesh file not found") from None
    if not stat.S_ISREG(st.st_mode):
        raise SasmiError(f"{where}: {path}: not a regular file (expected an OBJ, STL or PLY file)")
    if st.st_size > limits.MESH_MAX_BYTES:
        raise SasmiError(f"{where}: {path}: {st.st_size} bytes (allowed: <= {limits.MESH_MAX_BYTES} bytes)")


def target_height(t: Target) -> float | None:
    """Height of the target above its lowest point; None for meshes (known only once loaded)."""
    if t.shape in ("cylinder", "sphere"):
        return 2 * t.radius
    if t.shape == "cone":
        return t.length
    return None


# ---------------------------------------------------------------------------------------
# Presets: TOML with distributions
# ---------------------------------------------------------------------------------------

SECTIONS = {"sonar": Sonar, "seafloor": Seafloor, "post": Post}
TOP_KEYS = set(SECTIONS) | {"targets", "target_grid", "description"}


def _is_distribution(v: Any) -> bool:
    return isinstance(v, dict)


def _section(where: str) -> str:
    """"targets[3].yaw" -> "targets", "target_grid.target.yaw" -> "targets": the key of limits.FIELDS."""
    head = where.split(".")[0].split("[")[0]
    return "targets" if head == "targets" or where.startswith("target_grid.target") else head


def _check_value(cls: type, name: str, value: Any, where: str) -> Any:
    f = {f.name: f for f in dataclasses.fields(cls)}[name]
    allowed = f.metadata.get("allowed") or ""
    expected = type(f.default)
    if expected is float and isinstance(value, int) and not isinstance(value, bool):
        if abs(value) > 2**53:  # TOML integers are unbounded here; float() of a huge one overflows
            raise SasmiError(f"{where}: {value} is far too large (allowed: {allowed or 'a finite number'})")
        value = float(value)
    if expected is int and isinstance(value, float) and value.is_integer():
        value = int(value)
    if type(value) is not expected:
        raise SasmiError(f"{where}: expected {expected.__name__}, got {type(value).__name__} {value!r}"[:300])
    if expected is str and len(value) > limits.MAX_STRING:
        raise SasmiError(f"{where}: a string of {len(value)} characters (allowed: <= {limits.MAX_STRING})")
    if expected is float and not math.isfinite(value):
        raise SasmiError(f"{where}: {value!r} is not allowed (allowed: a finite number{', ' if allowed else ''}"
                         f"{allowed})")
    check = f.metadata.get("check")
    if check is not None and not check(value):
        raise SasmiError(f"{where}: {value!r} is not allowed (allowed: {allowed})")
    if expected in (int, float):
        limits.field_range(_section(where), name).check(value, where)  # the stated bound and its reason
    return value


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _check_distribution(cls: type, name: str, dist: dict, where: str) -> None:
    if len(dist) != 1 or next(iter(dist)) not in ("uniform", "normal", "choice"):
        raise SasmiError(f"{where}: a distribution is one of {{uniform = [lo, hi]}}, {{normal = [mean, std]}}, "
                         f"{{choice = [...]}}; got {dist!r}"[:300])
    kind, args = next(iter(dist.items()))
    if not isinstance(args, list) or not args:
        raise SasmiError(f"{where}.{kind}: expected a non-empty list")
    if kind == "choice":
        if len(args) > limits.MAX_CHOICES:
            raise SasmiError(f"{where}.choice: {len(args)} entries (allowed: <= {limits.MAX_CHOICES})")
        for v in args:
            _check_value(cls, name, v, where)
        return
    if len(args) != 2 or not all(_is_number(a) for a in args):
        raise SasmiError(f"{where}.{kind}: expected two numbers, got {args!r}"[:300])
    if not all(math.isfinite(a) for a in args):
        raise SasmiError(f"{where}.{kind}: {args!r} holds a value that is not a finite number")
    if kind == "uniform":
        if args[0] > args[1]:
            raise SasmiError(f"{where}.uniform: lower bound {args[0]} exceeds upper bound {args[1]}")
        for v in args:
            _check_value(cls, name, float(v) if isinstance(cls.__dataclass_fields__[name].default, float) else v, where)
    else:
        if args[1] < 0:
            raise SasmiError(f"{where}.normal: std {args[1]} is negative")
        # each draw is checked again; these bounds only stop draws that could never be in range
        r = limits.field_range(_section(where), name)
        r.check(args[0], f"{where}.normal mean")
        if r.lo is not None and r.hi is not None and args[1] > r.hi - r.lo:
            raise SasmiError(f"{where}.normal: std {args[1]:g} exceeds the whole allowed range "
                             f"(allowed: {r.allowed()})")


def _check_table(cls: type, table: Any, where: str, skip: tuple[str, ...] = ()) -> None:
    if not isinstance(table, dict):
        raise SasmiError(f"{where}: expected a table, got {type(table).__name__}")
    names = [f.name for f in dataclasses.fields(cls) if f.name not in skip]
    for key, value in table.items():
        if key not in names:
            raise SasmiError(f"{where}.{key}: unknown key (allowed: {', '.join(names)})")
        if _is_distribution(value):
            _check_distribution(cls, key, value, f"{where}.{key}")
        else:
            _check_value(cls, key, value, f"{where}.{key}")


def _draw(value: Any, rng: np.random.Generator) -> Any:
    if not _is_distribution(value):
        return value
    kind, args = next(iter(value.items()))
    if kind == "uniform":
        return float(rng.uniform(args[0], args[1]))
    if kind == "normal":
        return float(rng.normal(args[0], args[1]))
    return args[int(rng.integers(len(args)))]


def _sample_table(cls: type, table: dict, rng: np.random.Generator, where: str, **fixed: Any) -> Any:
    # Draw every distribution in the dataclass's field order so the draw sequence does not
    # depend on the order keys were written in the preset.
    values = dict(fixed)
    for f in dataclasses.fields(cls):
        if f.name in table:
            drawn = _draw(table[f.name], rng)
            if type(f.default) is int and isinstance(drawn, float):
                drawn = int(round(drawn))  # uniform/normal over an integer field draws integers
            values[f.name] = _check_value(cls, f.name, drawn, f"{where}.{f.name}")
    return cls(**values)


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
                _check_table(section, raw[name], name)
        targets = raw.get("targets", [])
        if not isinstance(targets, list):
            raise SasmiError("targets: expected an array of tables ([[targets]])")
        if len(targets) > limits.MAX_TARGETS:
            raise SasmiError(f"targets: {len(targets)} targets (allowed: <= {limits.MAX_TARGETS})")
        for i, t in enumerate(targets):
            _check_table(Target, t, f"targets[{i}]")
        if "description" in raw and not isinstance(raw["description"], str):
            raise SasmiError(f"description: expected a string, got {type(raw['description']).__name__}")
        if "target_grid" in raw:
            if not isinstance(raw["target_grid"], dict):
                raise SasmiError(f"target_grid: expected a table, got {type(raw['target_grid']).__name__}")
            grid = dict(raw["target_grid"])
            target = grid.pop("target", {})
            _check_table(TargetGrid, grid, "target_grid")
            _check_table(Target, target, "target_grid.target", skip=("x", "y"))
        preset = cls(raw=raw, path=path)
        preset.sample(0, 0)  # cross-field checks on one draw, so a broken preset fails at load
        return preset

    def resolve_mesh(self, mesh: str) -> Path:
        p = Path(mesh).expanduser()
        if not p.is_absolute() and self.path is not None:
            p = self.path.parent / p
        return p

    def sample(self, seed: int, index: int) -> Scene:
        rng = np.random.default_rng([seed, index])
        sonar = _sample_table(Sonar, self.raw.get("sonar", {}), rng, "sonar")
        seafloor = _sample_table(Seafloor, self.raw.get("seafloor", {}), rng, "seafloor")
        post = _sample_table(Post, self.raw.get("post", {}), rng, "post")
        targets = [_sample_table(Target, t, rng, f"targets[{i}]") for i, t in enumerate(self.raw.get("targets", []))]
        if "target_grid" in self.raw:
            targets += self._grid_targets(sonar, rng, len(targets))
        targets = [dataclasses.replace(t, mesh=str(self.resolve_mesh(t.mesh))) if t.shape == "mesh" and t.mesh else t
                   for t in targets]
        scene_seed = int(rng.integers(2**31 - 1))
        return Scene(sonar=sonar, seafloor=seafloor, targets=tuple(targets), post=post, seed=scene_seed).validate()

    def _grid_targets(self, sonar: Sonar, rng: np.random.Generator, first: int) -> list[Target]:
        grid_raw = dict(self.raw["target_grid"])
        target_raw = grid_raw.pop("target", {})
        grid = _sample_table(TargetGrid, grid_raw, rng, "target_grid")
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
                targets.append(_sample_table(Target, target_raw, rng, f"targets[{k}]", **xy))
        return targets


SCENES = Path(__file__).resolve().parent.parent / "scenes"  # the presets shipped beside the package


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


def read_small_file(path: Path, max_bytes: int, what: str) -> bytes:
    """The bytes of a regular file of at most `max_bytes`; checked before reading, so /dev/zero or a
    FIFO is refused instead of read for ever."""
    try:
        st = path.stat()
    except FileNotFoundError:
        raise SasmiError(f"{path}: {what} not found") from None
    except OSError as e:
        raise SasmiError(f"{path}: cannot read {what} ({e.strerror or e})") from None
    if not stat.S_ISREG(st.st_mode):
        kind = "a folder" if stat.S_ISDIR(st.st_mode) else "not a regular file"
        raise SasmiError(f"{path}: {kind} (expected a {what} file)")
    if st.st_size > max_bytes:
        raise SasmiError(f"{path}: {st.st_size} bytes is too large for a {what} (allowed: <= {max_bytes} bytes)")
    try:
        with open(path, "rb") as f:
            data = f.read(max_bytes + 1)
    except OSError as e:
        raise SasmiError(f"{path}: cannot read {what} ({e.strerror or e})") from None
    if len(data) > max_bytes:  # grew since stat
        raise SasmiError(f"{path}: too large for a {what} (allowed: <= {max_bytes} bytes)")
    return data


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

