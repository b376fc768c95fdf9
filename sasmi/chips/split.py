"""Train / validation split of a chip folder by the `scene_group` column of its MANIFEST.csv.

Chips of one scene group (one survey swath, one SAS tile) look alike, so a group goes
wholly to one side: a validation figure then measures chips from scenes the networks
never saw. The assignment is deterministic (same answer on every machine): groups are
visited in an order fixed by a hash of (seed, group name), and each joins validation
when that brings the validation share of every category (targets, seafloor) closer to
`fraction`.
"""
from __future__ import annotations

import csv
import hashlib
import io
import json
import os
import shutil
from collections import Counter, defaultdict
from dataclasses import dataclass, field
from pathlib import Path

from sasmi.errors import SasmiError
from sasmi.images import write_text

MANIFEST = "MANIFEST.csv"
REQUIRED_COLUMNS = ("file", "category", "scene_group")
SIDES = ("train", "validation")


@dataclass
class Split:
    """Chip files (relative to `root`, e.g. 'targets/x.png') per side, and the groups behind them."""
    root: Path
    fraction: float
    seed: int
    files: dict[str, list[str]] = field(default_factory=dict)   # side -> sorted relative paths
    groups: dict[str, list[str]] = field(default_factory=dict)  # side -> sorted scene groups
    manifest: list[dict[str, str]] = field(default_factory=list)  # ROOT/MANIFEST.csv's rows, as read

    def counts(self) -> dict[str, dict[str, int]]:
        """side -> category -> chip count."""
        return {side: dict(sorted(Counter(f.split("/")[0] for f in files).items()))
                for side, files in self.files.items()}

    def to_json(self) -> dict:
        return {"root": str(self.root), "fraction": self.fraction, "seed": self.seed,
                "counts": self.counts(), "groups": self.groups, "files": self.files}


def read_manifest(root: Path) -> list[dict[str, str]]:
    """Rows of ROOT/MANIFEST.csv; SasmiError when it, a needed column or a listed file is missing."""
    path = Path(root) / MANIFEST
    if not path.is_file():
        raise SasmiError(f"{path}: no {MANIFEST} (the split needs its scene_group column)")
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        missing = [c for c in REQUIRED_COLUMNS if c not in (reader.fieldnames or [])]
        if missing:
            raise SasmiError(f"{path}: missing column(s) {', '.join(missing)} (needs {', '.join(REQUIRED_COLUMNS)})")
        rows = list(reader)
    if not rows:
        raise SasmiError(f"{path}: lists no chips")
    for row in rows:
        if not row["scene_group"]:
            raise SasmiError(f"{path}: {row['file']} has an empty scene_group")
        if not (Path(root) / row["file"]).is_file():
            raise SasmiError(f"{path}: lists {row['file']}, which is not in {root}")
    return rows


def _order_key(seed: int, group: str) -> str:
    return hashlib.sha256(f"{seed}:{group}".encode()).hexdigest()


def split_chips(root: str | os.PathLike, fraction: float = 0.25, seed: int = 0) -> Split:
    """Assign whole scene groups of ROOT's MANIFEST to train (~1 - fraction) and validation (~fraction)."""
    if not 0.0 < fraction < 1.0:
        raise SasmiError(f"--fraction {fraction}: must lie strictly between 0 and 1")
    root = Path(root)
    rows = read_manifest(root)
    totals = Counter(r["category"] for r in rows)
    per_group: dict[str, Counter] = defaultdict(Counter)
    for r in rows:
        per_group[r["scene_group"]][r["category"]] += 1

    def error(val: Counter) -> float:
        return sum((val[c] / totals[c] - fraction) ** 2 for c in totals)

    validation: set[str] = set()
    val_counts: Counter = Counter()
    for group in sorted(per_group, key=lambda g: _order_key(seed, g)):
        if error(val_counts + per_group[group]) < error(val_counts):
            validation.add(group)
            val_counts += per_group[group]
    side_of = {g: ("validation" if g in validation else "train") for g in per_group}
    files = {side: sorted(r["file"] for r in rows if side_of[r["scene_group"]] == side) for side in SIDES}
    groups = {side: sorted(g for g in per_group if side_of[g] == side) for side in SIDES}
    return Split(root=root, fraction=fraction, seed=seed, files=files, groups=groups, manifest=rows)


def _link(src: Path, dst: Path) -> None:
    """A symlink to the real file; a hard link or a copy where the file system refuses symlinks."""
    try:
        dst.symlink_to(src.resolve())
    except OSError:
        try:
            os.link(src, dst)
        except OSError:
            shutil.copy2(src, dst)


def write_split(split: Split, out: str | os.PathLike) -> Path:
    """OUT/{train,validation}/CATEGORY/NAME linking to the real chips, each side's own MANIFEST.csv
    (so train can be split again, e.g. to tune a recipe on train alone), plus OUT/split.json."""
    out = Path(out)
    for side in SIDES:
        if (out / side).exists():
            raise SasmiError(f"--out {out}: {out / side} exists already (choose a new folder)")
    for side in SIDES:
        for rel in split.files[side]:
            dst = out / side / rel
            dst.parent.mkdir(parents=True, exist_ok=True)
            _link(split.root / rel, dst)
        chosen = set(split.files[side])
        table = io.StringIO()
        writer = csv.DictWriter(table, fieldnames=list(split.manifest[0]), lineterminator="\n")
        writer.writeheader()
        writer.writerows(r for r in split.manifest if r["file"] in chosen)
        write_text(out / side / MANIFEST, table.getvalue())
    write_text(out / "split.json", json.dumps(split.to_json(), indent=1) + "\n")
    return out
