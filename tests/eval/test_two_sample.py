"""The classifier two-sample test: 0.5 for two draws of one distribution, near 1 for a visible signature."""
from __future__ import annotations

import numpy as np

from sasmi.eval.config import TwoSampleConfig
from sasmi.eval.two_sample import resized, two_sample_auc

QUICK = TwoSampleConfig(folds=3, repeats=2, epochs=40, max_steps=80, size=32)


def _speckle(n, looks, seed, size=32):
    """(n, S, S) gamma speckle in [0, 1]: `looks` sets its texture, the mean stays 0.3."""
    return np.random.default_rng(seed).gamma(looks, 0.3 / looks, (n, size, size)).clip(0, 1).astype(np.float32)


def test_two_draws_of_one_distribution_score_about_one_half():
    result = two_sample_auc(_speckle(40, 6.0, 0), _speckle(120, 6.0, 1), QUICK)
    assert 0.35 < result["auc"] < 0.65, result["aucs"]
    assert len(result["aucs"]) == 6 and result["p_fake"].shape == (120,)


def test_large_sets_hold_out_some_folds_of_one_repeat():
    """From `large_from` chips on each side, held-out chips of a few folds pin the AUC: 2 classifiers, not 8.
    Each still learns from 3/4 of the chips, and only the chips it never saw get a probability."""
    cfg = TwoSampleConfig(folds=4, repeats=2, epochs=40, max_steps=20, size=32, large_from=50, large_scored_folds=2)
    small, large = (two_sample_auc(_speckle(n, 6.0, 0), _speckle(60, 6.0, 1), cfg) for n in (40, 60))
    assert (small["repeats"], len(small["aucs"]), small["scored_folds"]) == (2, 8, 4)
    assert not np.isnan(small["p_fake"]).any()
    assert (large["repeats"], len(large["aucs"]), large["scored_folds"]) == (1, 2, 2)
    assert np.isnan(large["p_fake"]).sum() == 30  # the 2 folds of 15 generated chips never held out


def test_a_texture_the_real_chips_lack_is_found():
    """Same mean and size, other speckle: φ-FID might miss it, a classifier does not."""
    result = two_sample_auc(_speckle(40, 6.0, 0), _speckle(120, 1.5, 1), QUICK)
    assert result["auc"] > 0.9, result["aucs"]


def test_the_most_synthetic_chips_are_the_odd_ones():
    fake = _speckle(60, 6.0, 1)
    fake[:5, 10:20, 10:20] = 1.0  # five chips carry a white block no real chip has
    result = two_sample_auc(_speckle(60, 6.0, 0), fake, TwoSampleConfig(folds=3, repeats=2, epochs=80, max_steps=150, size=32))
    assert set(np.argsort(-result["p_fake"])[:5]) == set(range(5))


def test_chips_are_shrunk_by_area():
    images = np.zeros((2, 64, 64), np.uint8)
    images[:, :32] = 255
    small = resized(images, 32)
    assert small.shape == (2, 32, 32) and small[:, :16].min() == 1.0 and small[:, 16:].max() == 0.0
    many = np.random.default_rng(0).integers(0, 256, (7, 64, 64), np.uint8)
    np.testing.assert_array_equal(resized(many, 32, block=3), resized(many, 32, block=7))  # block by block: the same


def _seeds_benchmark():
    """benchmarks/two_sample_seeds.py as a module."""
    from conftest import benchmark

    return benchmark("two_sample_seeds")


def test_hiding_the_target_band_judges_the_floor_alone():
    """benchmarks/two_sample_seeds.py --hide: a signature in the target band is seen with the floor hidden
    (`floor`) and not with the band hidden (`target`); one outside the band the other way round."""
    bench = _seeds_benchmark()
    real = _speckle(60, 6.0, 0)
    in_band, off_band = _speckle(60, 6.0, 1), _speckle(60, 6.0, 1)
    in_band[:, 14:16, 16:24] = 1.0   # a bright stripe where target chips have their target (rows 12-20, cols 10-)
    off_band[:, 2:4, 16:24] = 1.0    # the same stripe on the floor, above the band
    cfg = TwoSampleConfig(folds=3, repeats=1, epochs=80, max_steps=100, size=32)
    auc = {(name, hide): two_sample_auc(bench.hidden(real, hide), bench.hidden(fake, hide), cfg)["auc"]
           for name, fake in (("in band", in_band), ("off band", off_band)) for hide in ("target", "floor")}
    assert auc["in band", "floor"] > 0.9 and auc["off band", "target"] > 0.9, auc
    assert auc["in band", "target"] < 0.7 and auc["off band", "floor"] < 0.7, auc


def test_the_seeds_benchmark_refuses_a_set_drawn_down_to_one_chip(monkeypatch, capsys):
    """benchmarks/two_sample_seeds.py --most: fewer than 2 chips a set is one line and exit 2, before any chip is read."""
    bench = _seeds_benchmark()
    monkeypatch.setattr("sys.argv", ["two_sample_seeds.py", "--real", "nowhere", "--most", "1", "nowhere"])
    assert bench.main() == 2
    assert capsys.readouterr().err.strip() == "two_sample_seeds: --most 1: a set needs at least 2 chips"


def test_the_seeds_benchmark_draws_each_set_down_at_random(tmp_path, monkeypatch, capsys):
    """--most N: each set enters the test with N of its chips drawn without repeats, the same N on every run and
    not its first N by name (a real folder's first names are a few survey lines); a set of fewer with all of
    them, the real chips all of them."""
    from PIL import Image

    import sasmi.eval.two_sample as two_sample

    for name, count in (("real", 6), ("big", 20), ("small", 3)):
        (tmp_path / name).mkdir()
        for i in range(count):
            Image.fromarray(np.full((16, 16), 10 * i, np.uint8)).save(tmp_path / name / f"{i:02d}.png")
    seen = []

    def recorded(real, fake, cfg, seed=0):
        seen.append((len(real), [int(round(c.mean() * 255)) for c in fake]))
        return {"auc": 0.5}

    monkeypatch.setattr(two_sample, "two_sample_auc", recorded)
    monkeypatch.setattr("sys.argv", ["two_sample_seeds.py", "--real", str(tmp_path / "real"), "--seeds", "1",
                                     "--most", "4", str(tmp_path / "big"), str(tmp_path / "small")])
    assert _seeds_benchmark().main() == 0
    (real_big, big), (real_small, small) = seen
    assert real_big == real_small == 6 and small == [0, 10, 20], seen
    assert len(set(big)) == 4 and big == sorted(big) and set(big) <= {10 * i for i in range(20)}, big
    assert big != [0, 10, 20, 30], big   # not the first four by name
    seen.clear()
    assert _seeds_benchmark().main() == 0
    assert seen[0][1] == big, (seen, big)  # the same draw on every run
