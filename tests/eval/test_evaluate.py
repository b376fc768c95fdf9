"""Metrics with known answers: FID, KID, precision/recall, nearest neighbours (pure numpy, fast)."""
import numpy as np
import pytest
import scipy.linalg

from sasmi.eval import manifold as mf
from sasmi.eval import metrics as ev
from sasmi.eval import neighbours as nb


def exact_gaussian(rng, n, mean, cov):
    """n samples whose sample mean and covariance (ddof 1) are exactly `mean` and `cov`."""
    d = len(mean)
    z = rng.standard_normal((n, d))
    z -= z.mean(0)
    white = np.linalg.solve(np.linalg.cholesky(z.T @ z / (n - 1)), z.T).T  # sample covariance = I
    return white @ np.linalg.cholesky(cov).T + mean


def closed_form_fid(mu1, s1, mu2, s2):
    """The textbook formula with a general (complex-capable) sqrtm: an independent reference."""
    root1 = scipy.linalg.sqrtm(s1)
    cross = scipy.linalg.sqrtm(root1 @ s2 @ root1)
    return float(np.sum((mu1 - mu2) ** 2) + np.trace(s1) + np.trace(s2) - 2 * np.trace(cross).real)


def random_cov(rng, d):
    a = rng.standard_normal((d, d))
    return a @ a.T / d + 0.1 * np.eye(d)


def test_fid_of_a_set_with_itself_is_zero():
    rng = np.random.default_rng(0)
    for n, d in ((200, 16), (20, 64)):  # N > D and rank-deficient N < D
        x = rng.standard_normal((n, d)) * rng.uniform(0.1, 10, d)
        assert ev.fid(x, x) == pytest.approx(0.0, abs=1e-8 * np.trace(np.cov(x.T)))


def test_fid_matches_closed_form_for_gaussians():
    rng = np.random.default_rng(1)
    d = 8
    # 1-D: (μ1 − μ2)² + (σ1 − σ2)²
    a, b = exact_gaussian(rng, 300, np.array([1.0]), np.array([[4.0]])), exact_gaussian(rng, 500, np.array([-2.0]), np.array([[0.25]]))
    assert ev.fid(a, b) == pytest.approx(9.0 + (2.0 - 0.5) ** 2, abs=1e-6)
    # commuting (diagonal) covariances: ‖Δμ‖² + Σ (√λa − √λb)²
    la, lb = rng.uniform(0.1, 5, d), rng.uniform(0.1, 5, d)
    mu_a, mu_b = rng.standard_normal(d), rng.standard_normal(d)
    a, b = exact_gaussian(rng, 400, mu_a, np.diag(la)), exact_gaussian(rng, 250, mu_b, np.diag(lb))
    expected = np.sum((mu_a - mu_b) ** 2) + np.sum((np.sqrt(la) - np.sqrt(lb)) ** 2)
    assert ev.fid(a, b) == pytest.approx(expected, abs=1e-6)
    # general, non-commuting covariances, against scipy's sqrtm
    sa, sb = random_cov(rng, d), random_cov(rng, d)
    a, b = exact_gaussian(rng, 300, mu_a, sa), exact_gaussian(rng, 300, mu_b, sb)
    assert ev.fid(a, b) == pytest.approx(closed_form_fid(mu_a, sa, mu_b, sb), abs=1e-6)


def test_fid_mean_part_is_what_a_shift_removes():
    rng = np.random.default_rng(2)
    d = 6
    a = exact_gaussian(rng, 200, np.zeros(d), random_cov(rng, d))
    b = exact_gaussian(rng, 300, rng.standard_normal(d), random_cov(rng, d))
    mean_part = ev.fid_mean_part(a, b)
    assert mean_part == pytest.approx(np.sum((a.mean(0) - b.mean(0)) ** 2))
    aligned = a - a.mean(0) + b.mean(0)  # the same spread, no offset
    assert ev.fid(a, b) - mean_part == pytest.approx(ev.fid(aligned, b), abs=1e-6)
    assert ev.fid_mean_part(aligned, b) == pytest.approx(0.0, abs=1e-12)
    wider = a.mean(0) + 2 * (a - a.mean(0))  # the same mean, twice the spread
    assert ev.fid_mean_part(wider, b) == pytest.approx(mean_part)
    assert ev.fid(wider, b) > ev.fid(a, b) + 1


def test_fid_rank_deficient_matches_full_eigen_route():
    # N < D: the N×N route must equal the textbook D×D formula with symmetric square roots
    rng = np.random.default_rng(2)
    a, b = rng.standard_normal((30, 80)) + 0.3, 2 * rng.standard_normal((40, 80))

    def sym_sqrt(s):
        w, v = np.linalg.eigh(s)
        return (v * np.sqrt(np.clip(w, 0, None))) @ v.T

    sa, sb = np.cov(a.T), np.cov(b.T)
    root = sym_sqrt(sa)
    expected = np.sum((a.mean(0) - b.mean(0)) ** 2) + np.trace(sa) + np.trace(sb) - 2 * np.trace(sym_sqrt(root @ sb @ root))
    # the D×D reference itself carries √(round-off) from ~50 zero eigenvalues, hence 1e-7
    assert ev.fid(a, b) == pytest.approx(expected, rel=1e-7)
    # exact check: FID is invariant under an isometric embedding of 5-d sets (N > D) into 80-d (N < D)
    small_a, small_b = rng.standard_normal((30, 5)), rng.standard_normal((40, 5)) * 1.5 + 0.2
    q = np.linalg.qr(rng.standard_normal((80, 5)))[0]  # (80, 5), orthonormal columns
    assert ev.fid(small_a @ q.T, small_b @ q.T) == pytest.approx(ev.fid(small_a, small_b), rel=1e-9)


def test_fid_through_the_cholesky_factor_matches_a_qr_and_svd_of_the_data():
    # N > D: the Cholesky factor of the covariance and an eigenproblem, against the QR of the centred rows
    # and an SVD (the textbook-stable route), on covariances of condition up to 1e8
    rng = np.random.default_rng(6)
    d = 48
    basis = np.linalg.qr(rng.standard_normal((d, d)))[0]
    a = (rng.standard_normal((500, d)) * np.logspace(0, -4, d)) @ basis + 0.1
    b = (rng.standard_normal((700, d)) * np.logspace(0, -4, d) * 1.2) @ basis

    def qr_svd(x, y):
        fx, fy = (np.linalg.qr((v - v.mean(0)) / np.sqrt(len(v) - 1), mode="r") for v in (x, y))
        root = np.linalg.svd(fx @ fy.T, compute_uv=False).sum()
        return np.sum((x.mean(0) - y.mean(0)) ** 2) + np.sum(fx**2) + np.sum(fy**2) - 2 * root

    assert ev._cov_factor(a).invertible and ev._cov_factor(b).invertible
    assert ev.fid(a, b) == pytest.approx(qr_svd(a, b), rel=1e-9)
    # a constant feature makes the covariance singular: the QR route, and the FID of the other features
    padded_a, padded_b = np.c_[a, np.full(len(a), 3.0)], np.c_[b, np.full(len(b), 3.0)]
    assert not ev._cov_factor(padded_a).invertible
    assert ev.fid(padded_a, padded_b) == pytest.approx(ev.fid(a, b), rel=1e-9)


@pytest.mark.parametrize("n", [40, 300])  # fewer and more chips than φ's dimensions
def test_a_resample_counted_by_its_distinct_rows_has_the_fid_of_the_resample_itself(n):
    rng = np.random.default_rng(3)
    a, b = rng.standard_normal((n, 64)), rng.standard_normal((n, 64)) * 1.3 + 0.2
    rows_a, rows_b = rng.integers(0, n, n), rng.integers(0, n, n)
    counted = ev._fid_of(ev._resampled(a, rows_a), ev._resampled(b, rows_b))
    assert counted == pytest.approx(ev.fid(a[rows_a], b[rows_b]), rel=1e-9)
    assert counted != pytest.approx(ev.fid(a, b), rel=1e-3)  # a resample, not the sets


def test_fid_bootstrap_and_real_split():
    rng = np.random.default_rng(3)
    a, b = rng.standard_normal((100, 4)), rng.standard_normal((100, 4)) + 1.0
    est = ev.fid_bootstrap(a, b, n=30, seed=0)
    assert est.value == pytest.approx(ev.fid(a, b))
    assert 0 < est.std < est.value  # a clear shift of ‖Δμ‖² = 4 is far outside its own noise
    ref = ev.fid_real_split(a, n=30, seed=0)
    assert 0 < ref.value < 0.5 * est.value and ref.std > 0


def test_kid_unbiased_near_zero_for_one_distribution_and_positive_when_shifted():
    rng = np.random.default_rng(4)
    a, b = rng.standard_normal((400, 16)), rng.standard_normal((400, 16))
    same = ev.kid(a, b, subsets=50, subset_size=50, seed=0)
    shifted = ev.kid(a, b + 0.5, subsets=50, subset_size=50, seed=0)
    assert abs(same.value) < 3 * same.std / np.sqrt(50) + 1e-3  # zero within its standard error
    assert shifted.value > 10 * max(shifted.std / np.sqrt(50), abs(same.value))
    # unbiased at tiny sizes too, where FID is dominated by its bias
    tiny = np.mean([ev.mmd2_unbiased(rng.standard_normal((10, 16)), rng.standard_normal((10, 16)))
                    for _ in range(400)])
    assert abs(tiny) < 0.02


def test_precision_recall():
    rng = np.random.default_rng(5)
    real = rng.standard_normal((300, 2))
    p, r = mf.precision_recall(real, rng.standard_normal((300, 2)), k=3)
    assert p > 0.85 and r > 0.85
    collapsed = 0.05 * rng.standard_normal((300, 2))  # mode collapse: realistic but not diverse
    p, r = mf.precision_recall(real, collapsed, k=3)
    assert p > 0.95 and r < 0.3
    p, r = mf.precision_recall(real, rng.standard_normal((300, 2)) + 20, k=3)
    assert p == 0 and r == 0


def test_every_set_is_compared_on_the_same_real_splits(monkeypatch):
    from pathlib import Path

    from sasmi.eval.config import EvalConfig
    from sasmi.eval.features import FeatureSet
    from sasmi.eval.evaluate import realism_table

    rng = np.random.default_rng(9)
    def feature_set(name, n):
        return FeatureSet(name, Path(name), rng.integers(0, 255, (n, 8, 8), dtype=np.uint8), rng.standard_normal((n, 6)))

    halves = []  # the real half B of each FID left: per split, (set a, B), (A, B), then (set b, B)
    monkeypatch.setattr(ev, "fid", lambda a, b: halves.append(b.tobytes()) or 1.0)
    monkeypatch.setattr(ev, "fid_bootstrap", lambda *args, **kwargs: ev.Estimate(1.0, 0.0))
    monkeypatch.setattr(ev, "fid_real_split", lambda *args, **kwargs: ev.Estimate(1.0, 0.0))
    realism_table(feature_set("real", 40), [feature_set("a", 30), feature_set("b", 300)],
                  EvalConfig(bootstrap=5, kid_subsets=2))
    # both sets meet the same 5 splits, and FID(A, B) of each is computed once for both
    assert len(halves) == 3 * 5 and len(set(halves)) == 5 and all(halves.count(h) == 3 for h in halves)


def test_replicates_stop_once_the_mean_is_known_and_do_not_depend_on_the_cores(monkeypatch):
    rng = np.random.default_rng(12)
    real, close = rng.standard_normal((400, 8)), rng.standard_normal((400, 8)) + 0.3
    results = {}
    for workers in (1, 2):
        monkeypatch.setattr(ev, "cores", lambda: workers)
        results[workers] = (ev.fid_ratio_matched(close, real, n=300, seed=1), ev.fid_real_split(real, n=300, seed=1),
                            mf.precision_recall_matched(real, close[:300], k=3, n=300, seed=1))
    assert results[1] == results[2]
    calls = []
    values = ev.replicates(lambda v: calls.append(v) or v, lambda i: 1.0 + 0.01 * (i % 2), 500, ev.mean_known)
    assert len(values) == len(calls) == ev.MIN_REPLICATES  # a mean known at once stops at the minimum
    noisy = ev.replicates(lambda v: v, lambda i: rng.normal(0.0, 1.0), 500, ev.mean_known)
    assert len(noisy) == 500  # a standard error of 1/sqrt(500) is far above MC_ERROR: all are drawn


def test_recall_does_not_fall_as_more_chips_are_generated():
    # a perfect generator in many dimensions (φ has 1024): unmatched, its recall falls as it makes more
    rng = np.random.default_rng(8)
    real = rng.standard_normal((40, 256))
    few, many = rng.standard_normal((40, 256)), rng.standard_normal((800, 256))  # the real distribution
    _, recall_few = mf.precision_recall_matched(real, few, k=3, n=30)
    _, recall_many = mf.precision_recall_matched(real, many, k=3, n=30)
    _, recall_real = mf.precision_recall_real_split(real, k=3, n=30)
    assert mf.precision_recall(real, many, k=3)[1] < recall_few.value - 0.1  # the balls shrink
    assert abs(recall_many.value - recall_few.value) < 0.1
    assert abs(recall_many.value - recall_real.value) < 0.15 and recall_many.std > 0
    collapsed = 0.05 * rng.standard_normal((800, 256))  # still caught at equal sizes
    precision, recall = mf.precision_recall_matched(real, collapsed, k=3, n=50)
    assert precision.value > 0.9 and recall.value < 0.2


def test_real_halves_from_one_distance_matrix_equal_halves_computed_apart(monkeypatch):
    rng = np.random.default_rng(9)
    real = rng.standard_normal((90, 64))
    shared = mf.precision_recall_real_split(real, k=3, n=20, seed=4)  # 90² distances: one matrix
    monkeypatch.setattr(mf, "DENSE_BYTES", 0)  # each split's distances computed apart, as for large sets
    apart = mf.precision_recall_real_split(real, k=3, n=20, seed=4)
    assert [e.value for e in shared] == pytest.approx([e.value for e in apart], abs=1e-12)
    assert [e.std for e in shared] == pytest.approx([e.std for e in apart], abs=1e-12) and shared[0].std > 0


def test_coverage_finds_the_real_chips_no_generated_chip_is_near():
    rng = np.random.default_rng(11)
    covered, missed = rng.standard_normal((30, 8)), rng.standard_normal((10, 8)) + 12  # a mode the set lacks
    generated = rng.standard_normal((200, 8))
    cover = mf.real_coverage(np.concatenate([covered, missed]), generated, k=3, n=20)
    assert cover.shape == (40,) and cover[:30].mean() > 0.7 and np.all(cover[30:] == 0)
    _, recall = mf.precision_recall_matched(np.concatenate([covered, missed]), generated, k=3, n=200)
    assert abs(cover.mean() - recall.value) < 0.05  # its mean is the realism table's recall


def test_coverage_report_names_the_missed_chips(tmp_path):
    from pathlib import Path

    from sasmi.eval.config import EvalConfig
    from sasmi.eval.coverage import FIGURE, coverage_metrics
    from sasmi.eval.features import FeatureSet

    rng = np.random.default_rng(12)
    phi = np.concatenate([rng.standard_normal((12, 4)), rng.standard_normal((3, 4)) + 9])  # chips 12-14 missed
    real = FeatureSet("real", Path("real"), rng.integers(0, 255, (15, 8, 8), dtype=np.uint8), phi,
                      tuple(f"chip{i}.png" for i in range(15)))
    made = FeatureSet("made", Path("made"), rng.integers(0, 255, (60, 8, 8), dtype=np.uint8),
                      rng.standard_normal((60, 4)))
    c = coverage_metrics(real, [made], EvalConfig(least_covered_shown=3, coverage_draws=10), tmp_path)["made"]
    assert {x["chip"] for x in c["least"]} == {"chip12.png", "chip13.png", "chip14.png"} and c["never"] == 3
    assert all(x["covered"] == 0 and x["nearest"].startswith("#") for x in c["least"])
    assert (tmp_path / FIGURE).is_file()


def test_nearest_and_copy_statistics():
    rng = np.random.default_rng(6)
    real = rng.standard_normal((50, 8))
    idx, dist = nb.nearest(real[:5] + 1e-6, real, k=2)
    assert list(idx[:, 0]) == [0, 1, 2, 3, 4] and np.all(dist[:, 0] < 1e-5)
    idx, _ = nb.nearest(real, real, k=1, exclude_self=True)
    assert np.all(idx[:, 0] != np.arange(50))
    real_nn = nb.nearest(real, real, 1, exclude_self=True)[1][:, 0]
    copies = nb.nearest(real[:20] + 1e-3 * rng.standard_normal((20, 8)), real, 1)[1][:, 0]
    fresh = nb.nearest(rng.standard_normal((20, 8)), real, 1)[1][:, 0]
    assert nb.copy_statistics(copies, real_nn)["fraction_below"] == 1.0
    stats = nb.copy_statistics(fresh, real_nn)
    assert stats["fraction_below"] < 0.3 and 0.5 < stats["median_ratio"] < 2.0


def dense_distances(a, b):
    """The plain N × N reference for the blocked code: every distance at once, in float64."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return np.sqrt(np.clip((a**2).sum(1)[:, None] + (b**2).sum(1)[None, :] - 2.0 * a @ b.T, 0.0, None))


def dense_precision_recall(real, fake, k):
    def radius(x):
        d = dense_distances(x, x)
        np.fill_diagonal(d, np.inf)
        return np.partition(d, k - 1, axis=1)[:, k - 1]

    d = dense_distances(fake, real)
    return np.mean((d <= radius(real)[None, :]).any(1)), np.mean((d.T <= radius(fake)[None, :]).any(1))


@pytest.mark.parametrize("block_bytes", [8 * 7 * 60, nb.BLOCK_BYTES])  # 7 rows a block, and one block
def test_blocked_neighbours_equal_the_dense_matrix(monkeypatch, block_bytes):
    monkeypatch.setattr(nb, "BLOCK_BYTES", block_bytes)
    rng = np.random.default_rng(7)
    real, fake = rng.standard_normal((60, 12)), rng.standard_normal((45, 12)) * 1.2 + 0.3
    assert mf.precision_recall(real, fake, k=3) == pytest.approx(dense_precision_recall(real, fake, 3), abs=0)
    assert 0 < mf.precision_recall(real, fake, k=3)[0] < 1  # not a trivial all-or-nothing case
    d = dense_distances(fake, real)
    idx, dist = nb.nearest(fake, real, k=4)
    np.testing.assert_array_equal(idx, np.argsort(d, axis=1)[:, :4])
    np.testing.assert_allclose(dist, np.sort(d, axis=1)[:, :4], rtol=1e-12)
    d = dense_distances(real, real)
    np.fill_diagonal(d, np.inf)
    idx, dist = nb.nearest(real, real, k=2, exclude_self=True)
    np.testing.assert_array_equal(idx, np.argsort(d, axis=1)[:, :2])
    np.testing.assert_allclose(dist, np.sort(d, axis=1)[:, :2], rtol=1e-12)
    # 8-bit pixels of 128 px chips (blocked in the reference as well), compared in float32: the float64
    # distances to 1e-3 of full scale rms, a chip one gray level from a real one included (a copy)
    pixels = rng.integers(0, 256, (30, 128 * 128), dtype=np.uint8)
    query = np.concatenate([pixels[:4], np.clip(pixels[4:8].astype(int) + rng.integers(-1, 2, (4, 128 * 128)),
                                                 0, 255).astype(np.uint8)])
    idx, dist = nb.nearest(query, pixels, k=3)
    d = dense_distances(query, pixels)
    np.testing.assert_array_equal(idx, np.argsort(d, axis=1)[:, :3])
    np.testing.assert_allclose(dist, np.sort(d, axis=1)[:, :3], rtol=0, atol=1e-3 * 255 * 128)
    assert np.all(dist[:, 0] <= 128)  # the copies found, each within one gray level rms


def test_the_evaluations_gray_level_distance_is_the_gan_terms_energy_distance():
    import torch

    from sasmi.eval.evaluate import level_distance
    from sasmi.gan.losses import energy_distance

    gen = torch.Generator().manual_seed(0)
    a, b = torch.rand(50, 27, generator=gen), torch.rand(37, 27, generator=gen) * 0.8 + 0.1
    for x, y in ((a, b), (a[:25], a[25:])):  # apart, and two halves of one set (≈ 0)
        assert level_distance(x, y, block=7) == pytest.approx(float(energy_distance(x.double(), y.double())), abs=1e-9)


def test_the_evaluations_gray_levels_are_the_gan_terms_quantiles():
    import torch

    from sasmi.eval.evaluate import gray_levels
    from sasmi.gan.losses import gray_levels as gan_levels
    from sasmi.preprocess import unit_to_signed

    images = np.random.default_rng(7).integers(0, 256, (11, 20, 20), np.uint8)
    images[3] //= 4  # a dark chip: its quantiles fall between other order statistics
    expected = gan_levels(unit_to_signed(torch.from_numpy(images).float()[:, None] / 255.0))
    assert torch.allclose(gray_levels(images, block=4), expected, atol=1e-6)
