"""Preset values: the check of one field's value, distributions and their draws, reading a small file.

A preset field is declared in sasmi/scene/model.py (or sasmi/scene/preset.py) as a dataclass field whose metadata holds its
`check` (a predicate for the bounds that are part of its meaning) and `allowed` (the words
for them); sasmi/limits.py adds the finite upper bounds. Everything here works on any such
dataclass, so it knows nothing of sonar, seafloor or targets.

A value is a plain value or a distribution: `{uniform = [lo, hi]}`, `{normal = [mean, std]}`
or `{choice = [a, b, ...]}`.
"""
from __future__ import annotations

import dataclasses
import math
import stat
from pathlib import Path
from typing import Any

import numpy as np

from sasmi import limits
from sasmi.errors import SasmiError


def is_distribution(v: Any) -> bool:
    return isinstance(v, dict)


def _section(where: str) -> str:
    """"targets[3].yaw" -> "targets", "target_grid.target.yaw" -> "targets": the key of limits.FIELDS."""
    head = where.split(".")[0].split("[")[0]
    return "targets" if head == "targets" or where.startswith("target_grid.target") else head


def check_value(cls: type, name: str, value: Any, where: str) -> Any:
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
            check_value(cls, name, v, where)
        return
    if len(args) != 2 or not all(_is_number(a) for a in args):
        raise SasmiError(f"{where}.{kind}: expected two numbers, got {args!r}"[:300])
    if not all(math.isfinite(a) for a in args):
        raise SasmiError(f"{where}.{kind}: {args!r} holds a value that is not a finite number")
    if kind == "uniform":
        if args[0] > args[1]:
            raise SasmiError(f"{where}.uniform: lower bound {args[0]} exceeds upper bound {args[1]}")
        for v in args:
            check_value(cls, name, float(v) if isinstance(cls.__dataclass_fields__[name].default, float) else v, where)
    else:
        if args[1] < 0:
            raise SasmiError(f"{where}.normal: std {args[1]} is negative")
        # each draw is checked again; these bounds only stop draws that could never be in range
        r = limits.field_range(_section(where), name)
        r.check(args[0], f"{where}.normal mean")
        if r.lo is not None and r.hi is not None and args[1] > r.hi - r.lo:
            raise SasmiError(f"{where}.normal: std {args[1]:g} exceeds the whole allowed range "
                             f"(allowed: {r.allowed()})")


def check_field(cls: type, name: str, value: Any, where: str) -> None:
    """`value` of field `name` of `cls`, plain or a distribution, is allowed; else SasmiError naming `where`."""
    if is_distribution(value):
        _check_distribution(cls, name, value, where)
    else:
        check_value(cls, name, value, where)


def check_table(cls: type, table: Any, where: str, skip: tuple[str, ...] = ()) -> None:
    if not isinstance(table, dict):
        raise SasmiError(f"{where}: expected a table, got {type(table).__name__}")
    names = [f.name for f in dataclasses.fields(cls) if f.name not in skip]
    for key, value in table.items():
        if key not in names:
            raise SasmiError(f"{where}.{key}: unknown key (allowed: {', '.join(names)})")
        check_field(cls, key, value, f"{where}.{key}")


def draw(value: Any, rng: np.random.Generator) -> Any:
    if not is_distribution(value):
        return value
    kind, args = next(iter(value.items()))
    if kind == "uniform":
        return float(rng.uniform(args[0], args[1]))
    if kind == "normal":
        return float(rng.normal(args[0], args[1]))
    return args[int(rng.integers(len(args)))]


def sample_table(cls: type, table: dict, rng: np.random.Generator, where: str, **fixed: Any) -> Any:
    # Draw every distribution in the dataclass's field order so the draw sequence does not
    # depend on the order keys were written in the preset.
    values = dict(fixed)
    for f in dataclasses.fields(cls):
        if f.name in table:
            drawn = draw(table[f.name], rng)
            if type(f.default) is int and isinstance(drawn, float):
                drawn = int(round(drawn))  # uniform/normal over an integer field draws integers
            values[f.name] = check_value(cls, f.name, drawn, f"{where}.{f.name}")
    return cls(**values)


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


def check_mesh_file(path: Path, where: str) -> None:
    """A mesh must be a regular file of bounded size: trimesh would read /dev/zero for ever."""
    try:
        st = path.stat()
    except (OSError, ValueError):  # ValueError: a NUL character in the path
        raise SasmiError(f"{where}: {str(path)!r}: mesh file not found") from None
    if not stat.S_ISREG(st.st_mode):
        raise SasmiError(f"{where}: {path}: not a regular file (expected an OBJ, STL or PLY file)")
    if st.st_size > limits.MESH_MAX_BYTES:
        raise SasmiError(f"{where}: {path}: {st.st_size} bytes (allowed: <= {limits.MESH_MAX_BYTES} bytes)")


def target_kinds(raw: dict, kinds: type) -> tuple[list[dict], np.ndarray | None]:
    """The [[targets]] tables of preset `raw` without their `weight`, and the probability of drawing each
    (None: no top-level targets_per_chip, every table is one target). `kinds`: the dataclass declaring
    the fields targets_per_chip and weight."""
    tables = raw.get("targets", [])
    if "targets_per_chip" not in raw:
        for i, t in enumerate(tables):
            if isinstance(t, dict) and "weight" in t:
                raise SasmiError(f"targets[{i}].weight: only used with a top-level targets_per_chip "
                                 "(allowed: set targets_per_chip, or remove weight)")
        return tables, None
    check_field(kinds, "targets_per_chip", raw["targets_per_chip"], "targets_per_chip")
    if not tables:
        raise SasmiError("targets_per_chip: no [[targets]] tables to draw targets from (allowed: at least one)")
    plain = [{k: v for k, v in t.items() if k != "weight"} if isinstance(t, dict) else t for t in tables]
    return plain, _draw_probabilities(tables, kinds, "targets")


def seafloor_kinds(raw: dict, kinds: type) -> tuple[list[dict], np.ndarray | None]:
    """The seafloor tables of preset `raw`: [[seafloor]] kinds without their `weight` and the probability of
    drawing each, or one [seafloor] table (or none) and None. `kinds`: the dataclass declaring `weight`."""
    floor = raw.get("seafloor", {})
    if isinstance(floor, dict):
        return [floor], None
    if not isinstance(floor, list) or not floor:
        raise SasmiError("seafloor: expected a table ([seafloor]) or at least one [[seafloor]] table")
    for i, t in enumerate(floor):
        if not isinstance(t, dict):
            raise SasmiError(f"seafloor[{i}]: expected a table, got {type(t).__name__}")
    plain = [{k: v for k, v in t.items() if k != "weight"} for t in floor]
    return plain, _draw_probabilities(floor, kinds, "seafloor")


def _draw_probabilities(tables: list, kinds: type, section: str) -> np.ndarray:
    """Each kind table's `weight` (default 1) over the sum of them; errors name `section[i].weight`."""
    weights = []
    for i, t in enumerate(tables):
        w = t.get("weight", 1.0) if isinstance(t, dict) else 1.0
        if isinstance(w, dict):
            raise SasmiError(f"{section}[{i}].weight: a number, not a distribution (got {w!r})"[:300])
        weights.append(check_value(kinds, "weight", w, f"{section}[{i}].weight"))
    if sum(weights) <= 0:
        raise SasmiError(f"{section}: every weight is 0 (allowed: at least one [[{section}]] table with weight > 0)")
    return np.asarray(weights) / sum(weights)


def companion_kinds(raw: Any, settings: type, kinds: type, target: type) -> tuple[dict, list[dict], np.ndarray]:
    """A preset's [companions] table: its settings without `kinds`, its [[companions.kinds]] tables without
    their `weight`, and the probability of drawing each. `settings`, `kinds`, `target`: the dataclasses of
    the settings, of `weight` and of a target; the tables may not set x or y (companions are placed)."""
    if not isinstance(raw, dict):
        raise SasmiError(f"companions: expected a table ([companions]), got {type(raw).__name__}")
    settings_raw = {k: v for k, v in raw.items() if k != "kinds"}
    check_table(settings, settings_raw, "companions")
    tables = raw.get("kinds")
    if not isinstance(tables, list) or not tables:
        raise SasmiError("companions.kinds: expected at least one [[companions.kinds]] table")
    probabilities = _draw_probabilities(tables, kinds, "companions.kinds")
    plain = []
    for i, t in enumerate(tables):
        where = f"companions.kinds[{i}]"
        if not isinstance(t, dict):
            raise SasmiError(f"{where}: expected a table, got {type(t).__name__}")
        for key in ("x", "y"):
            if key in t:
                raise SasmiError(f"{where}.{key}: companions are placed at random over the chip "
                                 "(allowed: leave x and y out; companions.clearance keeps them apart)")
        if "role" in t:
            raise SasmiError(f"{where}.role: every companion has the role companion (allowed: leave role out)")
        plain.append({k: v for k, v in t.items() if k != "weight"})
        check_table(target, plain[-1], where)
    return settings_raw, plain, probabilities
