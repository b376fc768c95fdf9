"""The knobs `sasmi calibrate` turns: a preset's fields as numbers a derivative-free search can move.

A knob is a preset field ("post.gain") whose centre is searched over a physical range that holds any
sonar's value, so every start preset lies inside it; `targets.size`, `targets.burial`, `targets.range_offset` and
`targets.track_offset` are factors on every [[targets]] kind's sizes, burial depths, positions along range or along
track (1 = the start), and `targets.length` on their lengths alone (cylinders', boxes'): with `targets.size` it sets
their aspect. A moved chip size moves the targets' positions with it, so that they keep their place in the chip.
"FIELD.spread" searches how widely the field is drawn around its centre: uniform over centre x (1 ± spread), 0
being a fixed value. A knob left out keeps the start preset's value and spread. docs/calibrate.md lists them and
why each range.

A start preset with [[seafloor]] kinds: "seafloor.FIELD" sets FIELD alike in every kind, "seafloor[i].FIELD" in
kind i alone, and "seafloor[i].weight" searches kind i's weight (the other kinds keep theirs).
"""
from __future__ import annotations

import copy
import math
import re
from dataclasses import dataclass

import numpy as np

from sasmi.errors import SasmiError
from sasmi.scene.preset import SECTIONS


@dataclass(frozen=True)
class Knob:
    low: float
    high: float
    log: bool  # searched on a log scale: a factor of 2 weighs the same at any value
    ceiling: float | None = None  # largest value the field allows (albedo <= 1): draws are clipped to it
    whole: bool = False  # an integer field (rocks): draws are rounded


KNOBS: dict[str, Knob] = {
    "sonar.altitude": Knob(1.5, 30.0, True),
    "sonar.near_range": Knob(5.0, 150.0, True),
    "sonar.chip_size": Knob(3.0, 60.0, True),  # sets the pixel size: shadows and highlights in px
    "sonar.track_length": Knob(1.0, 50.0, True),
    "sonar.cone_angle": Knob(10.0, 80.0, False, 89.0),
    "seafloor.albedo": Knob(0.05, 0.95, True, 1.0),
    "seafloor.rms_height": Knob(0.001, 0.1, True),
    "seafloor.correlation_length": Knob(0.1, 10.0, True),
    "seafloor.rocks": Knob(0.0, 60.0, False, whole=True),
    "post.gain": Knob(0.03, 2.0, True),
    "post.tvg_strength": Knob(0.0, 1.0, False, 1.0),
    "post.noise_floor": Knob(0.0, 0.1, False),
    "post.speckle_looks": Knob(0.5, 30.0, True),
    "post.speckle_cell_range": Knob(0.0, 0.5, False),
    "post.speckle_cell_track": Knob(0.0, 0.5, False),
    "post.noise_std": Knob(0.0, 0.1, False),
    "post.gain_swing": Knob(0.0, 0.3, False),  # sd of the log gain from ping to ping
    "post.speckle_wander": Knob(0.0, 0.5, False),  # sd of the log of the speckle's contrast from patch to patch
    "targets.size": Knob(0.25, 4.0, True),  # a factor on every size of every [[targets]] kind
    "targets.burial": Knob(0.0, 1.0, False),  # a factor on every kind's burial: no deeper than the start's,
                                              # which keeps every draw's target above the floor
    # a factor on every kind's y: real target chips are cut centred on the contact, and a chip's pixel size moves
    # with sonar.chip_size, so a target's offset in pixels needs a knob of its own
    "targets.track_offset": Knob(0.02, 4.0, True),
    # and on every kind's x: real target chips are cut with the contact nearer than the centre column, so that its
    # shadow falls in the chip
    "targets.range_offset": Knob(0.02, 4.0, True),
}
# searched only when named: what some seabeds show and others not at all. Sand ripples: stripes a few px apart that
# neither φ nor the statistics see but a classifier tells from real MILCO chips at once (docs/calibrate.md), or sand
# waves metres apart whose crests bend (SASSED); a floor whose backscatter varies in patches, which moved renders off
# the MILCO chips (docs/matching.md); two sediments with sharp boundaries between them
NAMED_ONLY = {
    "seafloor.ripple_amplitude": Knob(0.0, 0.2, False),  # sand waves cast shadows from about 0.05 m
    "seafloor.ripple_wavelength": Knob(0.2, 10.0, True),
    "seafloor.ripple_direction": Knob(0.0, 180.0, False),  # a start's spread of 1 draws over [0, 2 x centre]
    "seafloor.ripple_sinuosity": Knob(0.0, 0.5, False),
    "seafloor.ripple_sharpness": Knob(1.0, 8.0, True),  # 8: crests above half height over a fifth of a wavelength
    "seafloor.patchiness": Knob(0.0, 1.5, False, 2.0),
    "seafloor.patch_size": Knob(0.3, 20.0, True),
    "seafloor.mosaic_contrast": Knob(0.1, 10.0, True),  # 1: one sediment; darker or brighter second ones alike
    "seafloor.mosaic_share": Knob(0.0, 1.0, False, 1.0),
    "seafloor.mosaic_size": Knob(0.5, 30.0, True),
    # the rocks' size, which no statistic pins: searched by default, the rocks shrank to a pixel or two across, where a
    # classifier tells the floor, so a search keeps the start's sizes unless named (docs/calibrate.md)
    "seafloor.rock_radius": Knob(0.03, 1.0, True),
    # a factor on every kind's length alone: targets.size scales a target whole, so a search cannot lengthen a shadow
    # along range (height) without widening it along track (length); real MILCO shadows are long and narrow
    "targets.length": Knob(0.25, 4.0, True),
}
KNOBS.update(NAMED_ONLY)
SPREAD = Knob(0.0, 0.9, False)  # "FIELD.spread": half-width of the draws / centre
WEIGHT = Knob(0.1, 10.0, True)  # "seafloor[i].weight": a kind from a tenth to ten times as common as a kind of weight 1
KIND = re.compile(r"seafloor\[(\d+)\]\.(.+)")  # "seafloor[1].ripple_amplitude": kind 1 of [[seafloor]] alone
# burial scales with the sizes: a target x m keeps its share buried, so no draw buries it whole
TARGET_SIZES = ("length", "radius", "width", "height", "tube_radius", "radius_top", "scale", "burial")
TARGET_FIELDS = {"targets.size": TARGET_SIZES, "targets.burial": ("burial",), "targets.track_offset": ("y",),
                 "targets.range_offset": ("x",), "targets.length": ("length",)}
DEFAULT_KNOBS = (*(k for k in KNOBS if k not in NAMED_ONLY), "post.gain.spread", "seafloor.albedo.spread",
                 "sonar.altitude.spread")


def kind_of(name: str) -> tuple[str, int | None]:
    """"seafloor[1].albedo.spread" -> ("seafloor.albedo.spread", 1); any other knob -> (name, None)."""
    m = KIND.fullmatch(name)
    return (f"seafloor.{m.group(2)}", int(m.group(1))) if m else (name, None)


def knob(name: str) -> Knob:
    field, kind = kind_of(name)  # a kind's knob is its field's, but for its weight
    if field == "seafloor.weight" and kind is not None:
        return WEIGHT
    if field.endswith(".spread") and field[:-len(".spread")] in KNOBS and not field.startswith("targets."):
        return SPREAD
    if field not in KNOBS:
        raise SasmiError(f"--params: unknown parameter {name} (allowed: {', '.join(KNOBS)}, and FIELD.spread "
                         "for each field outside targets; with [[seafloor]] kinds, seafloor[i].FIELD and "
                         "seafloor[i].weight)")
    return KNOBS[field]


def named_knobs(text: str) -> tuple[str, ...]:
    """--params as written: comma-separated knobs, "default" standing for DEFAULT_KNOBS wherever it appears
    ("default,post.tvg_strength.spread" searches one knob more than the default)."""
    names: list[str] = []
    for name in (part.strip() for part in text.split(",")):
        names.extend(DEFAULT_KNOBS if name == "default" else (name,) if name else ())
    return tuple(names)


def check_knobs(names: tuple[str, ...]) -> tuple[str, ...]:
    if not names:
        raise SasmiError("--params: no parameter given")
    for name in names:
        knob(name)
    if len(set(names)) != len(names):
        raise SasmiError(f"--params: {', '.join(names)} names a parameter twice")
    for name in names:
        field, kind = kind_of(name)
        if kind is not None and field in names:
            raise SasmiError(f"--params: {name} and {field} (every kind alike) both set kind {kind}'s field "
                             f"(allowed: one of them)")
    return names


def centre(value) -> float:
    """The middle of a preset value: itself, a uniform's midpoint, a normal's mean, a choice's mean."""
    if not isinstance(value, dict):
        return float(value)
    kind, args = next(iter(value.items()))
    return float(sum(args) / len(args)) if kind in ("uniform", "choice") else float(args[0])


def spread(value) -> float:
    """Half-width of a value's draws over its centre: 0 for a fixed value, 1 for uniform [0, 2c]."""
    c = centre(value)
    if not isinstance(value, dict) or c == 0:
        return 0.0
    kind, args = next(iter(value.items()))
    if kind == "uniform":
        return (args[1] - args[0]) / 2 / abs(c)
    if kind == "normal":
        return math.sqrt(3.0) * args[1] / abs(c)  # the uniform of the same std
    return (max(args) - min(args)) / 2 / abs(c)


def preset_value(raw: dict, section: str, key: str):
    """The value of [section] key in preset `raw`, or its default."""
    return _value(raw.get(section, {}), f"{section}.{key}")


def _tables(raw: dict, name: str, create: bool = False) -> list[dict]:
    """The preset tables knob `name` sets: its section's; every [[seafloor]] kind's, or kind i's alone for
    "seafloor[i]...". `create`: add a missing section to `raw` (which `apply` then writes)."""
    field, kind = kind_of(name)
    section = field.split(".")[0]
    value = raw.get(section)
    if section == "seafloor" and isinstance(value, list):
        if kind is None:
            return value
        if kind >= len(value):
            raise SasmiError(f"--params: {name}: the start preset has {len(value)} [[seafloor]] kinds "
                             f"(allowed: seafloor[0] to seafloor[{len(value) - 1}])")
        return [value[kind]]
    if kind is not None:
        raise SasmiError(f"--params: {name}: the start preset has one [seafloor] table (allowed: {field}, or "
                         "[[seafloor]] kinds in the preset)")
    return [raw.setdefault(section, {}) if create else raw.get(section, {})]


def _value(table: dict, field: str):
    """The value of `field` ("seafloor.albedo", or a kind's "seafloor.weight") in one table, or its default."""
    section, key = field.split(".")
    return table.get(key, 1.0 if key == "weight" else SECTIONS[section].__dataclass_fields__[key].default)


def start_values(raw: dict, names: tuple[str, ...]) -> dict[str, float]:
    """Each knob's value in the start preset `raw`, clipped into its range (a field set in every [[seafloor]]
    kind alike: the mean over the kinds)."""
    raw = explicit_geometry(raw)
    values = {}
    for name in names:
        if name.startswith("targets."):
            value = 1.0
        else:
            field = kind_of(name)[0].removesuffix(".spread")
            measure = spread if name.endswith(".spread") else centre
            value = float(np.mean([measure(_value(t, field)) for t in _tables(raw, name)]))
        k = knob(name)
        values[name] = min(max(value, k.low), k.high)
    return values


def explicit_geometry(raw: dict) -> dict:
    """`raw` with sonar.altitude written out (0 means max_range / 10): moving max_range so that a moved
    chip stays in range must not move the array."""
    sonar = raw.get("sonar", {})
    if centre(sonar.get("altitude", 0.0)) > 0:
        return raw
    raw = copy.deepcopy(raw)
    raw.setdefault("sonar", {})["altitude"] = float(f"{preset_value(raw, 'sonar', 'max_range') / 10:.6g}")
    return raw


def _rounded(v: float, whole: bool) -> float | int:
    return int(round(v)) if whole else float(f"{v:.4g}")  # 4 digits: a preset people read


def _with_centre_and_spread(value, c: float, s: float | None, k: Knob):
    """A value centred on `c`; a uniform over c x (1 ± s) when s > 0 (s None: keep the value's own spread)."""
    def clip(v: float) -> float | int:
        v = max(v, 0.0)
        return _rounded(min(v, k.ceiling) if k.ceiling is not None else v, k.whole)

    if isinstance(value, dict) and "choice" in value and s is None:
        old = centre(value)
        return {"choice": [clip(v * c / old if old else c) for v in value["choice"]]}
    s = spread(value) if s is None else s
    if s <= 0:
        return clip(c)
    return {"uniform": [clip(c * (1 - s)), clip(c * (1 + s))]}


def _scaled(value, factor: float, whole: bool = False):
    """A value or distribution with every number times `factor` (a normal's mean and std)."""
    if not isinstance(value, dict):
        return _rounded(value * factor, whole)
    kind, args = next(iter(value.items()))
    return {kind: [_rounded(a * factor, whole) for a in args]}


def _scale_targets(raw: dict, keys: tuple[str, ...], factor: float) -> None:
    """Every [[targets]] kind's (and a target grid's target's) `keys` times `factor`, in place."""
    for table in [*raw.get("targets", []), raw.get("target_grid", {}).get("target", {})]:
        for key in keys:
            if key in table:  # a size left out keeps its default: it may not apply to the shape
                table[key] = _scaled(table[key], factor)


def apply(raw: dict, values: dict[str, float]) -> dict:
    """A copy of preset `raw` with every knob set; max_range grows when the chip would leave it, and the targets'
    positions scale with the chip size: real chips are cut around their contacts in pixels, and a position left in
    metres would tie the targets' place in the chip to the pixel size."""
    start_chip = centre(preset_value(raw, "sonar", "chip_size"))
    raw = copy.deepcopy(explicit_geometry(raw))
    for name, v in values.items():
        if name.startswith("targets."):
            _scale_targets(raw, TARGET_FIELDS[name], v)
            continue
        field = kind_of(name)[0]
        if field == "seafloor.weight":
            _tables(raw, name)[0]["weight"] = _rounded(v, False)
            continue
        if name.endswith(".spread") and name[:-len(".spread")] in values:
            continue  # set with its centre
        centre_name = name.removesuffix(".spread")
        field = field.removesuffix(".spread")
        for table in _tables(raw, name, create=True):
            value = _value(table, field)
            # a spread whose centre is not searched keeps the start's centre
            c = values[centre_name] if centre_name in values else centre(value)
            table[field.split(".")[1]] = _with_centre_and_spread(value, c, values.get(f"{centre_name}.spread"),
                                                                 KNOBS[field])
    chip_ratio = centre(preset_value(raw, "sonar", "chip_size")) / start_chip
    if chip_ratio != 1:
        _scale_targets(raw, ("x", "y"), chip_ratio)
    sonar = raw["sonar"]
    far = max(_ends(preset_value(raw, "sonar", "near_range"))) + max(_ends(preset_value(raw, "sonar", "chip_size")))
    if preset_value(raw, "sonar", "max_range") < far:
        sonar["max_range"] = float(f"{far * 1.05:.4g}")
    return raw


def _ends(value) -> list[float]:
    if not isinstance(value, dict):
        return [float(value)]
    kind, args = next(iter(value.items()))
    return [args[0] - 4 * args[1], args[0] + 4 * args[1]] if kind == "normal" else [float(a) for a in args]
