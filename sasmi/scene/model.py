"""Scene description: plain frozen dataclasses, one scene each; presets (sasmi/scene/preset.py) draw them.

No renderer is imported here; both renderers (Mitsuba, POV-Ray) read the same `Scene`.

Coordinates: x is ground range (m), increasing to the right of the image, the sonar
track is off the left edge at x = 0; y is along-track (m), image rows; z is up.
Target positions are given relative to the chip centre.

Every field is declared with `spec`: its default, its check and the allowed range that an
error message quotes, and a line of documentation (sasmi/scene/values.py reads them).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

from sasmi.errors import SasmiError
from sasmi.scene.values import check_mesh_file

SHAPES = ("cylinder", "sphere", "cone", "box", "torus", "boulder", "mesh")
BACKSCATTER = ("lambert", "lambert2", "rough")
ROLES = ("target", "companion")
# the size fields each shape is made from (sasmi.render.geometry); a target's label keeps these alone, so
# that a box does not carry the radius default as if it had one (ATR results are stratified by size)
SIZE_FIELDS = {"cylinder": ("length", "radius"), "sphere": ("radius",), "cone": ("length", "radius", "radius_top"),
               "box": ("length", "width", "height"), "torus": ("radius", "tube_radius"),
               "boulder": ("length", "width", "height", "lumpiness"), "mesh": ("mesh", "scale")}
_OTHER_SIZES = {shape: set().union(*SIZE_FIELDS.values()) - set(fields) for shape, fields in SIZE_FIELDS.items()}


def positive(v: float) -> bool:
    return v > 0


def nonneg(v: float) -> bool:
    return v >= 0


def unit(v: float) -> bool:
    return 0 <= v <= 1


def spec(default: Any, check: Callable[[Any], bool] | None = None, allowed: str = "", doc: str = "") -> Any:
    return field(default=default, metadata={"check": check, "allowed": allowed, "doc": doc})


@dataclass(frozen=True)
class Sonar:
    max_range: float = spec(60.0, positive, "> 0", "m; the array flies at altitude max_range / 10 unless altitude is set")
    near_range: float = spec(30.0, nonneg, ">= 0", "m; ground range of the chip's left edge")
    chip_size: float = spec(6.0, positive, "> 0", "m; ground extent of the square chip")
    track_length: float = spec(20.0, positive, "> 0", "m; synthetic aperture, centred on the chip")
    emitters: int = spec(32, positive, ">= 1", "spot lights evenly spaced along the track")
    cone_angle: float = spec(30.0, lambda v: 0 < v < 90, "in (0, 90)", "deg; beam half-angle (cutoff)")
    intensity: float = spec(1.0, positive, "> 0", "source level, relative to the calibrated exposure")
    altitude: float = spec(0.0, nonneg, ">= 0", "m; height of the array above the seafloor; 0 = max_range / 10")
    slant_range: bool = spec(False, None, "true or false", "image x axis in slant range from the track "
                             "(layover, foreshortening), as a sonar forms images; false: ground range")
    aperture_angle: float = spec(0.0, lambda v: 0 <= v < 90, "in [0, 90)",
                                 "deg; > 0: beams look broadside with this along-track width, so the synthetic "
                                 "aperture grows with range (track_length is then derived); 0: spots aim at the chip")

    @property
    def array_altitude(self) -> float:
        """m; `altitude`, or max_range / 10 (the paper's geometry) when it is 0."""
        return self.altitude or self.max_range / 10.0


@dataclass(frozen=True)
class Seafloor:
    albedo: float = spec(0.5, unit, "in [0, 1]", "Lambertian reflectance of the sediment")
    rms_height: float = spec(0.01, nonneg, ">= 0", "m; rms of the power-law rough surface")
    correlation_length: float = spec(0.5, positive, "> 0", "m; roll-off scale of the roughness spectrum")
    spectral_exponent: float = spec(3.5, positive, "> 0", "power-law exponent of the roughness spectrum")
    ripple_amplitude: float = spec(0.0, nonneg, ">= 0", "m; sand-ripple amplitude")
    ripple_wavelength: float = spec(0.8, positive, "> 0", "m")
    ripple_direction: float = spec(0.0, None, "", "deg; direction of the ripple wave vector from +x (range)")
    ripple_sinuosity: float = spec(0.0, nonneg, ">= 0", "sd of the crests' sideways wander, in wavelengths, over "
                                   "about a wavelength along them (0: straight crests)")
    ripple_sharpness: float = spec(1.0, lambda v: v >= 1, ">= 1", "the crests' profile ((1 + sin) / 2)^sharpness: "
                                   "1 a sinusoid, larger narrower crests between flat troughs (sand waves); the "
                                   "crests stay ripple_amplitude above the mean level")
    rocks: int = spec(0, nonneg, ">= 0", "number of rock/clutter bumps")
    rock_radius: float = spec(0.15, positive, "> 0", "m; size of each bump")
    backscatter: str = spec("lambert", lambda v: v in BACKSCATTER, "one of " + ", ".join(BACKSCATTER),
                            "scattering law: lambert (cos of incidence, as today), lambert2 (cos^2, Lambert's law), "
                            "rough (cos^0.5, nearly even: rock and rubble)")
    patchiness: float = spec(0.0, lambda v: 0 <= v <= 2, "in [0, 2]", "std / mean of the sediment's backscatter "
                             "strength over the floor (a gamma texture under the speckle: K-distributed clutter); "
                             "0 = uniform; above 2 most of the floor renders black")
    patch_size: float = spec(1.0, positive, "> 0", "m; width (FWHM) of the patches of stronger and weaker backscatter")
    mosaic_contrast: float = spec(1.0, positive, "> 0", "backscatter of a second sediment / the first's, laid in "
                                  "patches with sharp boundaries (1: one sediment)")
    mosaic_share: float = spec(0.5, unit, "in [0, 1]", "share of the floor the second sediment covers, on average")
    mosaic_size: float = spec(5.0, positive, "> 0", "m; width (FWHM) of the sediments' patches")
    name: str = spec("", None, "", "what this seabed is ('sand waves'), written to each chip's labels: with "
                     "[[seafloor]] kinds, the kind the chip drew")

    @property
    def has_relief(self) -> bool:
        """Rough or rippled: a floor whose relief can be scaled (flat when both heights are 0)."""
        return bool(self.rms_height or self.ripple_amplitude)


@dataclass(frozen=True)
class Target:
    shape: str = spec("cylinder", lambda v: v in SHAPES, "one of " + ", ".join(SHAPES))
    x: float = spec(0.0, None, "", "m from the chip centre along range")
    y: float = spec(0.0, None, "", "m from the chip centre along track")
    yaw: float = spec(0.0, None, "", "deg; axis angle from +x (range) towards +y (along-track)")
    burial: float = spec(0.0, nonneg, ">= 0", "m of the target's height below the local seafloor")
    length: float = spec(2.0, positive, "> 0", "m; cylinder length, cone height, box or boulder length (along its axis)")
    radius: float = spec(0.3, positive, "> 0", "m; cylinder/sphere radius, cone base radius, torus major radius "
                         "(ring centre to tube centre)")
    radius_top: float = spec(0.1, nonneg, ">= 0", "m; top radius of the truncated cone")
    width: float = spec(1.0, positive, "> 0", "m; box or boulder width (across its axis)")
    height: float = spec(0.5, positive, "> 0", "m; box or boulder height")
    lumpiness: float = spec(0.3, lambda v: 0 <= v < 0.9, "in [0, 0.9)", "boulder: how far its surface strays from "
                            "a smooth ellipsoid: its largest lump as a share of its radius (the default preset: 0.4-0.85)")
    tube_radius: float = spec(0.15, positive, "> 0", "m; torus tube radius (a tyre lying flat: its height is twice this)")
    mesh: str = spec("", None, "", "OBJ/STL/PLY path (shape = 'mesh'), relative to the preset")
    scale: float = spec(1.0, positive, "> 0", "scale applied to a mesh file")
    albedo: float = spec(0.9, unit, "in [0, 1]")
    backscatter: str = spec("lambert", lambda v: v in BACKSCATTER, "one of " + ", ".join(BACKSCATTER),
                            "scattering law, as seafloor.backscatter: rough keeps a boulder's top bright at low grazing")
    # an ATR model learns contacts, and a real chip is cut around one: a companion of the same shape (another
    # pipe, a boulder) is clutter to it, so labels and exports say which is which
    role: str = spec("target", lambda v: v in ROLES, "one of " + ", ".join(ROLES),
                     "the contact the chip is cut around, or another object in view ([companions] draws those)")


@dataclass(frozen=True)
class Post:
    gain: float = spec(0.45, positive, "> 0",
                       "gray level of a flat albedo-1 seafloor at the chip centre lit by the array at intensity 1")
    speckle_looks: float = spec(0.0, nonneg, ">= 0", "L of gamma-distributed multiplicative speckle; 0 = off")
    noise_std: float = spec(0.0, nonneg, ">= 0", "std of additive Gaussian noise in gray levels (0..1)")
    tvg: bool = spec(True, None, "true or false",
                     "time-varying gain: divide out the flat-floor spreading and grazing loss, as sonars do")
    tvg_strength: float = spec(1.0, unit, "in [0, 1]",
                               "share of the TVG (an exponent): 1 evens out a flat floor, below 1 a range fall-off remains")
    noise_floor: float = spec(0.0, nonneg, ">= 0",
                              "gray level of the background under every echo (reverberation, ambient noise); "
                              "speckled with it, it is the mean level of acoustic shadows")
    speckle_cell_range: float = spec(0.0, nonneg, ">= 0", "m; resolution cell along range; speckle is correlated "
                                     "over it (0 = independent per pixel)")
    speckle_cell_track: float = spec(0.0, nonneg, ">= 0", "m; resolution cell along track (0 = independent per pixel)")
    speckle_wander: float = spec(0.0, nonneg, ">= 0", "sd of the log of the speckle's contrast from patch to patch "
                                 "(0 = equally grainy everywhere)")
    speckle_wander_length: float = spec(1.0, positive, "> 0",
                                        "m over which the speckle's contrast wanders (a Gaussian's sigma)")
    gain_swing: float = spec(0.0, nonneg, ">= 0", "sd of the log gain from ping to ping: rows along track brighter "
                             "or darker as a whole (0 = off)")
    gain_swing_length: float = spec(1.5, positive, "> 0",
                                    "m along track over which the gain swings (a Gaussian's sigma)")


@dataclass(frozen=True)
class TargetGrid:
    """Targets on a regular grid over the chip (the paper's target field)."""
    spacing: float = spec(5.0, positive, "> 0", "m between grid points")
    jitter: float = spec(0.0, nonneg, ">= 0", "m; uniform random offset of each target")


@dataclass(frozen=True)
class Scene:
    sonar: Sonar = Sonar()
    seafloor: Seafloor = Seafloor()
    targets: tuple[Target, ...] = ()
    post: Post = Post()
    seed: int = 0  # drives the heightfield, rocks, speckle and the sampler

    def validate(self, names: tuple[str, ...] = (), floor: str = "seafloor") -> "Scene":
        """Cross-field checks; raises SasmiError naming the field. `names[i]`: the preset table of target i
        (targets drawn by kind come from the table of their kind); default targets[i]. `floor`: the table of
        the seafloor (seafloor[k] for a kind of [[seafloor]])."""
        s = self.sonar
        if s.near_range + s.chip_size > s.max_range:
            raise SasmiError(f"sonar.near_range: chip far edge {s.near_range + s.chip_size:g} m exceeds "
                             f"sonar.max_range {s.max_range:g} m")
        f = self.seafloor
        relief = 4 * f.rms_height + f.ripple_amplitude + (1.4 * f.rock_radius if f.rocks else 0.0)
        altitude = f"{s.array_altitude:g} m" + ("" if s.altitude else " (sonar.max_range / 10)")
        if relief >= s.array_altitude:  # the floor would hide the array: a black chip, not an error, otherwise
            raise SasmiError(f"{floor}: relief up to {relief:g} m (4 rms_height + ripple_amplitude + 1.4 rock_radius) "
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


def scene_to_dict(scene: Scene) -> dict:
    """Every field of the scene; of each target, only the size fields of its shape (SIZE_FIELDS)."""
    record = dataclasses.asdict(scene)
    record["targets"] = [{k: v for k, v in t.items() if k not in _OTHER_SIZES[t["shape"]]} for t in record["targets"]]
    return record

