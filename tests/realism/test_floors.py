"""Renders on real floors: the floor outside the target, the render's ratios inside, a visible highlight,
floors chosen by their statistics (`sasmi fit --floors` end to end: tests/realism/test_fit.py)."""
from __future__ import annotations

import numpy as np
import pytest

from sasmi.realism.floors import BANDS, FLOOR_CHOICES, FloorsAhead, fresh_floor, matching_floors, on_floor
from sasmi.images import write_gray

SIZE = 64


def _scene(floor_level: float = 0.3):
    """A flat render (floor 0.3) with a target at 3x the floor and a shadow at 0.1 of it, and its mask."""
    mask = np.zeros((SIZE, SIZE), np.uint8)
    mask[28:34, 20:24] = 1
    mask[28:34, 24:44] = 2
    render = np.full((SIZE, SIZE), floor_level, np.float32)
    render[mask == 1] = 3 * floor_level
    render[mask == 2] = 0.1 * floor_level
    return render, mask


def _speckle(level: float, seed: int, looks: float = 4.0) -> np.ndarray:
    return np.random.default_rng(seed).gamma(looks, level / looks, (SIZE, SIZE)).astype(np.float32)


def test_on_floor_keeps_the_real_floor_and_the_renders_ratios():
    render, mask = _scene()
    floor = _speckle(0.2, 0)
    out = on_floor(render, mask, floor)
    far = np.ones_like(mask, bool)
    far[20:42, 12:52] = False
    np.testing.assert_array_equal(out[far], floor[far])  # away from the target: the real floor untouched
    level = np.median(floor)
    assert np.median(out[mask == 2]) / level == pytest.approx(0.1, rel=0.25)  # the shadow's 0.1 of the floor
    assert np.median(out[mask == 1]) / level > 2.5                            # the highlight's 3x or more


def test_on_floor_lifts_the_highlight_above_a_rocky_floors_bright_tail():
    """Without the lift the target sits under the floor's bright tail: `sasmi evaluate` counts it lost."""
    render, mask = _scene()
    floor = _speckle(0.2, 1)
    for r in range(2, SIZE, 10):  # rocks: 3 x 3 px at full scale, brighter than the target's 3x the floor
        for c in range(2, SIZE, 10):
            floor[r:r + 3, c:c + 3] = 1.0
    out = on_floor(render, mask, floor)
    from scipy.ndimage import gaussian_filter

    blurred = gaussian_filter(out.astype(np.float64), 1.5)
    assert blurred[mask == 1].max() > np.percentile(blurred[mask == 0], 99)


def test_on_floor_lifts_a_faint_highlight_out_of_the_speckle():
    """A render whose target peaks under its floor's bright tail is lifted to VISIBLE (1.1 x the tail) on a real floor."""
    from scipy.ndimage import gaussian_filter

    render, mask = _scene()
    render = _speckle(0.3, 4, looks=2.0) * np.where(mask == 1, 1.2, render / 0.3)  # target 1.2x a rough floor
    out = on_floor(np.clip(render, 0, 1), mask, _speckle(0.2, 5, looks=2.0))
    blurred = gaussian_filter(out.astype(np.float64), 1.5)
    assert blurred[mask == 1].max() > 1.09 * np.percentile(blurred[mask == 0], 99)


def test_on_floor_lifts_a_faint_companion_beside_a_bright_target():
    """Each target is lifted on its own: a dim companion far from a bright target is found too (one lift
    for the brightest alone leaves the companion under the floor's bright tail)."""
    from scipy.ndimage import gaussian_filter

    render, mask = _scene()
    mask[6:12, 40:44], mask[6:12, 44:52] = 1, 2  # a companion up the chip with its shadow
    render = _speckle(0.3, 6, looks=2.0) * np.where(mask == 1, 1.0, render / 0.3)
    render[28:34, 20:24] = 0.95                  # the target itself: far above the floor
    render[mask == 2] = 0.03
    out = on_floor(np.clip(render, 0, 1), mask, _speckle(0.2, 7, looks=2.0))
    blurred = gaussian_filter(out.astype(np.float64), 1.5)
    tail = np.percentile(blurred[mask == 0], 99)
    assert blurred[28:34, 20:24].max() > 1.09 * tail
    assert blurred[6:12, 40:44].max() > tail  # found by `sasmi evaluate`: unlifted it sits under the tail


def test_matching_floors_picks_the_targets_sonar(tmp_path):
    """Target chips and one floor folder share dark, fine speckle; a second sonar's floors are bright ripples."""
    targets, floors = tmp_path / "targets", tmp_path / "floors"
    cols = np.arange(SIZE)[None, :]
    for i in range(6):
        render, _ = _scene()
        write_gray(targets / f"t{i}.png", _speckle(0.15, 10 + i) * (render / 0.3))
        write_gray(floors / f"same_{i}.png", _speckle(0.15, 20 + i))
        ripples = 0.55 + 0.3 * np.sin(2 * np.pi * cols / 8.0 + i)
        write_gray(floors / f"other_{i}.png", _speckle(1.0, 30 + i, looks=20.0) * ripples)
    picks = matching_floors(floors, targets, SIZE)
    assert len(picks) == 6 * FLOOR_CHOICES and all(p.name.startswith("same_") for p in picks), [p.name for p in picks]


def test_matching_floors_keeps_the_next_nearest_floor_too(tmp_path):
    """One target chip: both floors of its sonar are kept, not only the nearest (the nearest alone gives the
    composites few distinct floors), and no floor of the other sonar."""
    targets, floors = tmp_path / "targets", tmp_path / "floors"
    cols = np.arange(SIZE)[None, :]
    render, _ = _scene()
    write_gray(targets / "t.png", _speckle(0.15, 10) * (render / 0.3))
    for i in range(2):
        write_gray(floors / f"same_{i}.png", _speckle(0.15, 20 + i))
    for i in range(4):
        write_gray(floors / f"other_{i}.png", _speckle(1.0, 30 + i, looks=20.0) * (0.55 + 0.3 * np.sin(2 * np.pi * cols / 8.0 + i)))
    assert sorted(p.name for p in matching_floors(floors, targets, SIZE)) == ["same_0.png", "same_1.png"]


def test_matching_floors_picks_the_targets_range_fall_off(tmp_path):
    """Target chips darken along range (far / near about 0.7, as a partial TVG leaves them); of two floors alike
    in everything else, the one that darkens the same way is picked, not the flat one."""
    targets, floors = tmp_path / "targets", tmp_path / "floors"
    fall_off = np.linspace(1.2, 0.8, SIZE)[None, :]  # columns are ground range
    for i in range(6):
        render, _ = _scene()
        write_gray(targets / f"t{i}.png", _speckle(0.15, 10 + i) * (render / 0.3) * fall_off)
        write_gray(floors / f"falling_{i}.png", _speckle(0.15, 20 + i) * fall_off)
        write_gray(floors / f"flat_{i}.png", _speckle(0.15, 30 + i))
    picks = matching_floors(floors, targets, SIZE)
    assert all(p.name.startswith("falling_") for p in picks), [p.name for p in picks]


def test_fresh_floor_keeps_the_seabed_and_not_the_pixels():
    """A floor with bands along range and a bright patch: the same seabed up to a gain per row, other speckle
    (the copying detector's pixels)."""
    from scipy.ndimage import gaussian_filter

    cols, rows = np.arange(SIZE)[None, :], np.arange(SIZE)[:, None]
    seabed = 0.15 + 0.2 * (cols / SIZE) + 0.15 * ((rows - 20) ** 2 + (cols - 40) ** 2 < 100)
    floor = np.clip(_speckle(1.0, 3) * seabed, 0, 1).astype(np.float32)
    fresh = fresh_floor(floor, floor, np.random.default_rng(0))
    assert fresh.shape == floor.shape and fresh.min() >= 0 and fresh.max() <= 1
    blur = lambda x: gaussian_filter(x.astype(np.float64), 4.0)
    row_gain = np.median(blur(fresh) / blur(floor), axis=1, keepdims=True)            # the gain bands' share
    assert np.abs(blur(fresh) / row_gain - blur(floor)).mean() < 0.1 * blur(floor).mean()  # bands, patch stay
    speckle, new = floor / seabed - 1, fresh / (seabed * row_gain) - 1
    assert abs(np.corrcoef(speckle.ravel(), new.ravel())[0, 1]) < 0.2               # the pixels are not the chip's
    assert new.std() == pytest.approx(speckle.std(), rel=0.2)                       # at the chip's speckle strength


def test_fresh_floor_lays_the_second_chips_speckle_on_the_first_chips_seabed():
    """Seabed chip: level 0.4, one-look speckle; speckle chip: level 0.2, sixteen looks. The floor has the first's
    level and the second's speckle strength (1/sqrt(looks))."""
    seabed_chip = np.clip(_speckle(0.4, 1, looks=1.0), 0, 1)
    speckle_chip = _speckle(0.2, 2, looks=16.0)
    fresh = fresh_floor(seabed_chip, speckle_chip, np.random.default_rng(0)).astype(np.float64)
    assert fresh.mean() == pytest.approx(seabed_chip.mean(), rel=0.25)                # not the second chip's 0.2
    assert fresh.std() / fresh.mean() == pytest.approx(0.25, rel=0.3)               # not the first chip's 1.0


def test_fresh_floor_swings_gain_along_track_and_not_along_range():
    """Flat chips without speckle: what is left is the gain bands. Each row is flat along range, the rows
    differ along track as slow swings (neighbouring rows alike), and their spread stays within BANDS."""
    flat = np.full((SIZE, SIZE), 0.3, np.float32)
    spreads = []
    for seed in range(20):
        rows = np.log(fresh_floor(flat, flat, np.random.default_rng(seed)).astype(np.float64) / 0.3)
        assert np.allclose(rows, rows[:, :1], atol=1e-6)                           # nothing along range
        profile = rows[:, 0]
        spreads.append(profile.std())
        if profile.std() > 0.02:
            assert np.corrcoef(profile[:-1], profile[1:])[0, 1] > 0.9               # slow swings, not row noise
    assert 0.03 < np.mean(spreads) and max(spreads) <= 1.2 * BANDS


def test_floor_label_names_the_chips_floor_for_lays_and_drops_the_renders_rocks(tmp_path):
    from sasmi.realism.floors import floor_for, floor_label
    from sasmi.labels import ChipLabel

    # four floor chips told apart by their level: the composite's floor level says which was its seabed
    choices = []
    for i, level in enumerate((0.1, 0.2, 0.4, 0.8)):
        write_gray(tmp_path / f"f{i}.png", np.full((32, 32), level, np.float32))
        choices.append(tmp_path / f"f{i}.png")
    rock = {"kind": "rock", "pixel_centre": [5.0, 5.0], "radius": 2.0, "bbox": [3, 3, 8, 8]}
    label = ChipLabel(index=0, size=32, scene={"seed": 1}, clutter=(rock,), extra={"kept": 1})
    for index in range(8):
        floor = floor_label(label, choices, seed=3, index=index).extra["floor"]
        seabed_level = float(np.median(floor_for(choices, 3, index, 32)))
        assert floor["seabed"] == str(choices[int(np.argmin([abs(seabed_level - lv) for lv in (0.1, 0.2, 0.4, 0.8)]))])
    relabelled = floor_label(label, choices, seed=3, index=0)
    assert relabelled.clutter == () and relabelled.extra["kept"] == 1 and relabelled.scene == label.scene
    assert "clutter" not in relabelled.to_json() and relabelled.to_json()["floor"]["speckle"] in map(str, choices)


def test_on_floor_gives_a_clipped_highlight_the_floors_grain():
    """A render's highlight clipped to flat white comes out speckled as its floor, bent under white (no pixel at 1)."""
    render, mask = _scene()
    render[mask == 1] = 1.0
    floor = _speckle(0.2, 8)
    out = on_floor(render, mask, floor)
    highlight = out[mask == 1]
    assert highlight.max() < 1.0
    contrast = lambda x: x.std() / x.mean()
    assert contrast(highlight) > 0.6 * contrast(floor)  # looks 4: 0.5
    assert np.median(highlight) > 2 * np.median(floor)   # and still bright


def test_display_bend():
    from sasmi.realism.display import KNEE, bent

    v = np.linspace(0.0, 3.0, 3001)
    out = bent(v, 0.9)
    np.testing.assert_array_equal(out[v <= KNEE * 0.9], v[v <= KNEE * 0.9])  # the bulk of a chip untouched
    assert out.max() < 0.9 and (np.diff(out) > 0).all()                     # under the ceiling, order kept
    step = np.diff(out) / np.diff(v)
    assert step[np.searchsorted(v, KNEE * 0.9)] == pytest.approx(1.0, abs=0.01)  # no kink at the knee
    np.testing.assert_array_equal(bent(v, np.inf), v)
    with np.errstate(all="raise"):  # a black chip's ceiling: no division by zero
        np.testing.assert_array_equal(bent(v, 0.0), np.zeros_like(v))


class _Drawn:
    """A floor_of that records which chips it drew, and on which thread."""

    def __init__(self):
        import threading

        self.calls, self._lock = [], threading.Lock()

    def __call__(self, index: int) -> np.ndarray:
        import threading

        with self._lock:
            self.calls.append((index, threading.current_thread().name))
        return np.full((4, 4), float(index), np.float32)

    def drawn(self) -> list[int]:
        return sorted(i for i, _ in self.calls)


def test_floors_ahead_draws_the_next_chips_on_its_thread_and_each_once():
    drawn = _Drawn()
    floors = FloorsAhead(drawn, list(range(10)), ahead=3)
    try:
        np.testing.assert_array_equal(floors(0), np.zeros((4, 4)))  # nothing drawn ahead yet: drawn here
        floors.draw_after(0)
        floors._pool.submit(lambda: None).result()  # the thread has drawn what was asked of it
        assert drawn.drawn() == [0, 1, 2, 3]
        assert all(name.startswith("floors") for i, name in drawn.calls if i > 0)  # ahead, on the thread
        for i in range(1, 10):
            np.testing.assert_array_equal(floors(i), np.full((4, 4), float(i)))
            floors.draw_after(i)
    finally:
        floors.close()
    assert drawn.drawn() == list(range(10))  # each chip once, none past the order


def test_floors_ahead_skips_chips_a_resumed_run_has_and_draws_out_of_order_ones_here():
    drawn = _Drawn()
    order = list(range(0, 40, 2))  # a shard's chips
    floors = FloorsAhead(drawn, order, ahead=2)
    try:
        for i in (10, 14, 12, 16, 30, 20):  # resumed at 10; workers finishing out of order; 18 never asked for
            np.testing.assert_array_equal(floors(i), np.full((4, 4), float(i)))
            floors.draw_after(i)
            floors._pool.submit(lambda: None).result()
    finally:
        floors.close()
    assert not {i for i, _ in drawn.calls} & {0, 2, 4, 6, 8}  # the chips the run had are not drawn
    assert set(drawn.drawn()) <= set(order)
    assert [drawn.drawn().count(i) for i in (12, 14, 16)] == [1, 1, 1]  # 12 asked for after 14, yet drawn once
