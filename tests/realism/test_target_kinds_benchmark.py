"""benchmarks/target_kinds.py: a calibrated preset with another preset's kinds of target, each at its size in
pixels and placed as the calibrated preset's, everything else as calibrated."""
from __future__ import annotations

import pytest

from sasmi.realism.preset_space import centre
from sasmi.scene.preset import load_preset

from conftest import benchmark


@pytest.fixture(scope="module")
def kinds():
    return benchmark("target_kinds")


def test_the_kinds_keep_their_size_in_pixels_and_the_rest_stays_calibrated(kinds, tmp_path):
    calibrated = load_preset("muscle_paper").raw  # a 6 m chip, one cylinder
    assert kinds.main(["muscle_paper", "cylinder_chip", "--out", str(tmp_path / "kinds.toml")]) == 0
    written = load_preset(tmp_path / "kinds.toml").raw
    source = load_preset("cylinder_chip").raw  # a 24 m chip, six kinds
    assert [t["shape"] for t in written["targets"]] == [t["shape"] for t in source["targets"]]
    for before, after in zip(source["targets"], written["targets"]):
        for key in ("length", "radius", "width", "height", "tube_radius", "burial"):
            if key in before:  # a quarter the metres on a quarter the chip
                assert centre(after[key]) == pytest.approx(centre(before[key]) / 4, rel=1e-3), key
        assert after.get("weight") == before.get("weight")
        assert (after["x"], after["y"]) == (calibrated["targets"][0]["x"], calibrated["targets"][0]["y"])
    for section in ("sonar", "seafloor", "post"):
        assert written[section] == calibrated[section]


def test_a_preset_without_targets_is_one_line_and_exit_2(kinds, tmp_path, capsys):
    out = tmp_path / "kinds.toml"
    assert kinds.main(["muscle_paper", "seafloor_only", "--out", str(out)]) == 2
    assert capsys.readouterr().err.strip() == "target_kinds: error: seafloor_only: no [[targets]] kinds to take"
    assert not out.exists()
