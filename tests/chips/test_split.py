"""`sasmi split`: whole scene groups per side, deterministic, ~75/25 per category, bad input in one line."""
from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

from sasmi.cli.main import main
from sasmi.errors import SasmiError
from sasmi.chips.split import split_chips


def _fake_root(tmp_path: Path, groups: dict[str, dict[str, int]], columns=("file", "category", "scene_group")) -> Path:
    """A chip folder with empty files: groups = {group: {category: count}}."""
    root = tmp_path / "chips"
    rows = []
    for group, per_cat in groups.items():
        for category, n in per_cat.items():
            (root / category).mkdir(parents=True, exist_ok=True)
            for i in range(n):
                rel = f"{category}/{group}_{i}.png"
                (root / rel).write_bytes(b"")
                rows.append({"file": rel, "category": category, "scene_group": group})
    with open(root / "MANIFEST.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(columns), extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    return root


def _fractions(split) -> dict[str, float]:
    c = split.counts()
    return {k: c["validation"].get(k, 0) / (c["validation"].get(k, 0) + c["train"].get(k, 0)) for k in c["train"]}


def test_split_of_the_shared_chips(real_chips):
    a, b = split_chips(real_chips), split_chips(real_chips)
    assert a.files == b.files and a.groups == b.groups  # deterministic
    assert not set(a.groups["train"]) & set(a.groups["validation"])
    for category, fraction in _fractions(a).items():
        assert 0.2 <= fraction <= 0.3, (category, fraction)
    assert split_chips(real_chips, seed=1).groups != a.groups  # the seed picks another split


def test_groups_never_straddle_and_categories_balance(tmp_path):
    groups = {f"g{i:02d}": {"targets": 1 + i % 5, "seafloor": 2 + (i * 7) % 3} for i in range(40)}
    groups.update({f"t{i}": {"targets": 3} for i in range(6)})
    root = _fake_root(tmp_path, groups)
    split = split_chips(root)
    by_group = {}
    for side, files in split.files.items():
        for rel in files:
            by_group.setdefault(Path(rel).name.rsplit("_", 1)[0], set()).add(side)
    assert all(len(sides) == 1 for sides in by_group.values())
    assert sum(len(f) for f in split.files.values()) == sum(sum(c.values()) for c in groups.values())
    for category, fraction in _fractions(split).items():
        assert abs(fraction - 0.25) < 0.05, (category, fraction)
    assert abs(_fractions(split_chips(root, fraction=0.5))["targets"] - 0.5) < 0.05


def test_cli_writes_linked_folders(tmp_path, capsys):
    root = _fake_root(tmp_path, {f"g{i}": {"targets": 2, "seafloor": 3} for i in range(12)})
    out = tmp_path / "split"
    assert main(["split", str(root), "--out", str(out)]) == 0
    info = json.loads((out / "split.json").read_text())
    for side in ("train", "validation"):
        for category in ("targets", "seafloor"):
            files = sorted(p.name for p in (out / side / category).iterdir())
            assert len(files) == info["counts"][side][category] > 0
            assert all((out / side / category / f).resolve() == (root / category / f).resolve() for f in files)
    assert main(["split", str(root), "--out", str(out)]) == 2  # never over an existing split
    assert "exists already" in capsys.readouterr().err
    # each side carries its own MANIFEST, so train can be split again (to tune on train alone)
    inner = tmp_path / "tune"
    assert main(["split", str(out / "train"), "--out", str(inner)]) == 0
    tune = json.loads((inner / "split.json").read_text())
    assert sorted(tune["groups"]["train"] + tune["groups"]["validation"]) == info["groups"]["train"]
    assert all(tune["counts"][side]["targets"] > 0 for side in ("train", "validation"))


def test_bad_input_is_one_line(tmp_path, capsys):
    root = _fake_root(tmp_path, {"g0": {"targets": 2}})
    (root / "targets" / "g0_1.png").unlink()
    with pytest.raises(SasmiError, match="g0_1.png"):
        split_chips(root)
    no_group = _fake_root(tmp_path / "b", {"g0": {"targets": 2}}, columns=("file", "category"))
    with pytest.raises(SasmiError, match="scene_group"):
        split_chips(no_group)
    assert main(["split", str(tmp_path / "nowhere"), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert "MANIFEST.csv" in err and "\n" not in err
    with pytest.raises(SasmiError, match="fraction"):
        split_chips(root, fraction=1.0)
