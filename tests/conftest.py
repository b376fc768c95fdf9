"""Shared fixtures: the real chips beside the checkout, tiny render sets, golden images."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_CHIPS = REPO.parent / "shared" / "data" / "sonar-chips"
FAILURES = REPO / "tests" / "_failures"


def benchmark(name: str):
    """benchmarks/NAME.py as a module, for tests of the figures' scripts."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(name, REPO / "benchmarks" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def temporary_files(folder: Path) -> list[Path]:
    """The temporary files of sasmi.images.atomic_path left under `folder`: a clean failure leaves none."""
    return [p for p in folder.rglob("*") if p.name.startswith(".") and ".tmp" in p.name]


def disk_full_at(monkeypatch, under: Path, k: int | None = None) -> list[str]:
    """Make the k-th rename into `under` (every one with k None) fail as a full disk does: every file sasmi writes
    is committed by one rename (sasmi.images.atomic_path). Returns the renames seen."""
    import errno
    import os

    seen, real_replace = [], os.replace

    def replace(src, dst, *args, **kwargs):
        if str(dst).startswith(str(under)):
            seen.append(str(dst))
            if k is None or len(seen) == k:
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real_replace(src, dst, *args, **kwargs)

    monkeypatch.setattr(os, "replace", replace)
    return seen


# Files that take minutes, longest first. `make test` runs the files on two workers (pytest-xdist,
# --dist loadfile) in collection order: started last, one of these would run on alone at the end.
LONG_FILES = ("test_notebooks.py", "test_calibrate.py", "test_fit.py", "test_sigterm.py", "test_fit_scene.py",
              "test_evaluate_report.py", "test_weights.py")


def pytest_collection_modifyitems(items):
    def rank(item) -> int:
        name = item.path.name
        return LONG_FILES.index(name) if name in LONG_FILES else len(LONG_FILES)

    items.sort(key=rank)  # stable: within a file and among the rest, the order stays


@pytest.fixture(autouse=True, scope="session")
def _torch_one_thread():
    """Tiny tensors on a machine of few cores beside Dr.Jit's own threads: more torch threads only wait on each other."""
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


@pytest.fixture
def quick_two_sample(monkeypatch):
    """`sasmi calibrate`'s report two-sample test (a few seconds of classifier training each) stood in by how far the
    renders' mean gray level lies from the real chips', as an AUC: for tests of the search, not of that test
    (tests/realism/test_calibrate.py tests it)."""
    import sasmi.realism.calibration_objective as objective

    monkeypatch.setattr(objective, "told_apart", lambda real, images, seed: {
        "auc": float(min(1.0, 0.5 + abs(np.mean(images) - np.mean(real)))), "auc_std": 0.0})


@pytest.fixture(scope="session")
def real_chips() -> Path:
    if not SHARED_CHIPS.is_dir():
        pytest.skip(f"real chips not found at {SHARED_CHIPS}")
    return SHARED_CHIPS


@pytest.fixture(scope="session")
def render_set(tmp_path_factory) -> Path:
    """8 chips of the paper geometry (targets large enough to measure at 32 px), rendered once per test session by the real renderer."""
    from sasmi.renderset.write import RenderJob, render_set as write_set
    from sasmi.scene.preset import load_preset

    out = tmp_path_factory.mktemp("renders") / "set"
    write_set(RenderJob(preset=load_preset(REPO / "scenes" / "muscle_paper.toml"), out=out, count=8,
                        size=32, spp=4), progress=False)
    return out


def assert_matches_golden(name: str, image: np.ndarray, mean_tol: float, max_tol: float) -> None:
    """Compare with tests/golden/NAME.npy; on failure write the image and |error| image to tests/_failures/."""
    from sasmi.images import write_gray

    golden = np.load(REPO / "tests" / "golden" / f"{name}.npy")
    err = np.abs(image.astype(np.float64) - golden)
    if err.mean() > mean_tol or err.max() > max_tol:
        FAILURES.mkdir(exist_ok=True)
        write_gray(FAILURES / f"{name}_actual.png", image)
        write_gray(FAILURES / f"{name}_golden.png", golden)
        write_gray(FAILURES / f"{name}_error.png", np.clip(err / max(err.max(), 1e-12), 0, 1))
        pytest.fail(f"{name}: mean |error| {err.mean():.4f} (tol {mean_tol}), max {err.max():.4f} (tol {max_tol}); "
                    f"images in {FAILURES}")
