"""Real chips cut from a local copy of their public sources, as a MANIFEST.csv describes them.

Each row names the chip (`file`, e.g. targets/x.png), its `source_file` (a path under SOURCE,
whose first folder is the repository as owner-name: PaweekornS-underwater_sonar/data/...), the
`crop_box` "col0,row0,col1,row1" (end exclusive) and whether the cut is `mirrored` left-right (so
that range grows to the right). A source is read as 8-bit luminance (Pillow's "L"); a cut that is
not `size` square is resized to it with Pillow's bicubic filter. Every row is checked before the
first chip is written: a missing source or a box outside its image names the row and writes nothing.
"""
from __future__ import annotations

import csv
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sasmi.errors import SasmiError
from sasmi.images import atomic_path

MANIFEST = "MANIFEST.csv"
COLUMNS = ("file", "source_file", "crop_box", "mirrored")
SHIPPED = {"sonar-chips": Path(__file__).resolve().parent / "sonar_chips.csv"}  # the MANIFEST of README's real chips


def manifest_path(text: str) -> Path:
    """A MANIFEST.csv, or the name of one that ships with sasmi."""
    return SHIPPED.get(text, Path(text))


@dataclass(frozen=True)
class Cut:
    file: str  # the chip, relative to the output folder
    source: Path
    box: tuple[int, int, int, int]  # col0, row0, col1, row1 (end exclusive)
    mirrored: bool


def read_manifest(path: Path, columns: tuple[str, ...] = COLUMNS, what: str = "--manifest ") -> list[dict[str, str]]:
    """The rows of a MANIFEST.csv; a SasmiError, prefixed by `what`, names a missing column."""
    try:
        rows = list(csv.DictReader(path.read_text().splitlines()))
    except (OSError, UnicodeDecodeError, csv.Error) as e:
        raise SasmiError(f"{what}{path}: cannot read ({e})") from None
    missing = [c for c in columns if not rows or c not in rows[0]]
    if missing:
        raise SasmiError(f"{what}{path}: no {', '.join(missing)} column (needs {', '.join(columns)})")
    return rows


def plan_cuts(rows: list[dict[str, str]], source: Path, manifest: Path) -> tuple[list[Cut], list[int]]:
    """Every row as a Cut; rows whose source file is absent are returned by line number."""
    from PIL import Image

    cuts, absent = [], []
    for line, row in enumerate(rows, start=2):
        where = f"--manifest {manifest}, line {line} ({row['file']})"
        file = Path(row["file"])
        if file.is_absolute() or ".." in file.parts or not file.name:
            raise SasmiError(f"{where}: file must be a path inside the output folder")
        try:
            box = tuple(int(v) for v in row["crop_box"].split(","))
        except ValueError:
            box = ()
        if len(box) != 4 or box[0] >= box[2] or box[1] >= box[3] or min(box) < 0:
            raise SasmiError(f"{where}: crop_box {row['crop_box']!r} is not col0,row0,col1,row1")
        if row["mirrored"] not in ("0", "1"):
            raise SasmiError(f"{where}: mirrored {row['mirrored']!r} is not 0 or 1")
        path = source / row["source_file"]
        if not path.is_file():
            absent.append(line)
            continue
        try:
            with Image.open(path) as image:
                width, height = image.size
        except (OSError, Image.DecompressionBombError) as e:
            raise SasmiError(f"{where}: cannot read {path} ({e})") from None
        if box[2] > width or box[3] > height:
            raise SasmiError(f"{where}: crop_box {row['crop_box']} lies outside {path} ({width}x{height})")
        cuts.append(Cut(row["file"], path, box, row["mirrored"] == "1"))
    return cuts, absent


def cut(c: Cut, size: int) -> np.ndarray:
    """(size, size) uint8: the chip as the MANIFEST describes it."""
    from PIL import Image, ImageOps

    with Image.open(c.source) as image:
        chip = image.convert("L").crop(c.box)
    if c.mirrored:
        chip = ImageOps.mirror(chip)
    if chip.size != (size, size):
        chip = chip.resize((size, size), Image.BICUBIC)
    return np.asarray(chip)


def build_chips(manifest: Path, source: Path, out: Path, size: int = 128, skip_missing: bool = False,
                log=print) -> dict:
    """OUT/<file> for every row, and OUT/MANIFEST.csv; a rerun writes only the chips not yet there."""
    from PIL import Image

    manifest, source, out = manifest_path(str(manifest)), Path(source), Path(out)
    if not source.is_dir():
        raise SasmiError(f"--source {source}: not a folder")
    rows = read_manifest(manifest)
    cuts, absent = plan_cuts(rows, source, manifest)
    if absent and not skip_missing:
        first = rows[absent[0] - 2]["source_file"]
        raise SasmiError(f"--manifest {manifest}, line {absent[0]}: source {source / first} is missing "
                         f"({len(absent)} rows in all; clone the repositories the MANIFEST names under --source, "
                         "or pass --skip-missing)")
    if absent:
        log(f"sasmi chips build: {len(absent)} rows left out, their sources missing under {source}")
    written = 0
    for c in cuts:
        target = out / c.file
        if target.is_file():
            continue
        chip = cut(c, size)
        with atomic_path(target) as tmp:
            Image.fromarray(chip).save(tmp, format="PNG")
        written += 1
    with atomic_path(out / MANIFEST) as tmp:
        shutil.copyfile(manifest, tmp)
    return {"rows": len(rows), "built": [c.file for c in cuts], "written": written, "absent": len(absent)}


def compare(out: Path, reference: Path, files: list[str]) -> list[str]:
    """The chips of `files` that differ from (or are absent in) `reference`, pixel for pixel."""
    from PIL import Image

    differ = []
    for file in files:
        ref = reference / file
        if not ref.is_file():
            differ.append(file)
            continue
        with Image.open(out / file) as a, Image.open(ref) as b:
            if a.size != b.size or not np.array_equal(np.asarray(a.convert("L")), np.asarray(b.convert("L"))):
                differ.append(file)
    return differ
