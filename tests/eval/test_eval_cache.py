"""The real set's φ cache: reused by a second evaluation, recomputed when a file or the φ run changes."""
import os

import numpy as np
import pytest
import torch

from sasmi.eval import cache
from sasmi.eval.features import load_set
from sasmi.images import write_gray


class CountingEncoder(torch.nn.Module):
    """A stand-in φ: (B, 1, 16, 16) in [-1, 1] → (B, 16); counts the images it encodes."""

    image_size = 16

    def __init__(self, seed=0):
        super().__init__()
        torch.manual_seed(seed)
        self.conv = torch.nn.Conv2d(1, 1, 4, stride=4)
        self.encoded = 0

    def forward(self, x):
        self.encoded += len(x)
        return self.conv(x).flatten(1)


@pytest.fixture
def folder(tmp_path):
    rng = np.random.default_rng(0)
    for i in range(5):
        write_gray(tmp_path / "real" / f"{i:03d}.png", rng.uniform(0, 1, (20, 24)))
    np.save(tmp_path / "real" / "005.npy", rng.uniform(0, 1, (20, 24)).astype(np.float32))  # fixed file size
    return tmp_path / "real"


def test_second_load_reads_the_cache(folder, tmp_path):
    encoder, lines = CountingEncoder(), []
    first = load_set("real", folder, encoder, cache_dir=tmp_path / "cache", log=lines.append)
    assert encoder.encoded == 6 and len(list((tmp_path / "cache").glob("real-*.npy"))) == 1
    second = load_set("real", folder, encoder, cache_dir=tmp_path / "cache", log=lines.append)
    assert encoder.encoded == 6  # nothing encoded the second time
    np.testing.assert_array_equal(second.phi, first.phi)  # float32 φ stored exactly
    assert second.phi.dtype == np.float64 and second.images.shape == (6, 16, 16)
    assert "from the cache" not in lines[0] and "from the cache" in lines[1]


@pytest.mark.parametrize("change", ["rewrite a file", "rewrite, same size", "add a file", "remove a file",
                                    "other weights"])
def test_cache_is_invalidated(folder, tmp_path, change):
    encoder = CountingEncoder()
    before = load_set("real", folder, encoder, cache_dir=tmp_path / "cache").phi
    if change == "rewrite a file":
        write_gray(folder / "002.png", np.full((20, 24), 0.5))
    elif change == "rewrite, same size":  # only the modification time tells
        path = folder / "005.npy"
        size, mtime = path.stat().st_size, path.stat().st_mtime_ns
        np.save(path, np.full((20, 24), 0.5, np.float32))
        os.utime(path, ns=(mtime + 10**9, mtime + 10**9))  # later, even on a coarse filesystem clock
        assert path.stat().st_size == size
    elif change == "add a file":
        write_gray(folder / "sub" / "new.png", np.full((20, 24), 0.5))
    elif change == "remove a file":
        (folder / "004.png").unlink()
    else:
        encoder = CountingEncoder(seed=1)
    encoder.encoded = 0
    after = load_set("real", folder, encoder, cache_dir=tmp_path / "cache").phi
    assert encoder.encoded == len(after)  # every image encoded afresh
    assert not np.array_equal(after, before) if change != "remove a file" else len(after) == 5
    assert len(list((tmp_path / "cache").glob("*.npy"))) == 2  # the old entry is kept, a new one written


def test_no_cache_dir_writes_nothing(folder, tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    encoder = CountingEncoder()
    load_set("real", folder, encoder)
    load_set("real", folder, encoder)
    assert encoder.encoded == 12 and not (tmp_path / "xdg").exists()
    assert cache.default_cache_dir() == tmp_path / "xdg" / "sasmi" / "phi"


def test_unreadable_cache_entry_is_recomputed(folder, tmp_path):
    encoder = CountingEncoder()
    first = load_set("real", folder, encoder, cache_dir=tmp_path / "cache").phi
    (entry,) = (tmp_path / "cache").glob("*.npy")
    entry.write_bytes(b"not an array")
    again = load_set("real", folder, encoder, cache_dir=tmp_path / "cache").phi
    assert encoder.encoded == 12
    np.testing.assert_array_equal(again, first)


def test_a_set_read_in_blocks_keeps_float_phi_and_8_bit_pixels(folder, monkeypatch):
    from sasmi.eval import features

    paths = features.image_paths(folder)
    whole = features.load_images(paths, CountingEncoder.image_size)  # (6, 16, 16) float32 in [0, 1]
    monkeypatch.setattr(features, "READ_BLOCK", 4)  # 6 images: blocks of 4 and 2
    encoder = CountingEncoder()
    s = load_set("real", folder, encoder)
    assert s.images.dtype == np.uint8 and np.array_equal(s.images, np.round(whole * 255).astype(np.uint8))
    # φ from the float images, not the 8-bit copy (the .npy chip has values between 8-bit levels)
    assert np.allclose(s.phi, features.phi_features(encoder, whole), atol=1e-6)
    assert not np.allclose(s.phi, features.phi_features(encoder, s.images / np.float32(255)), atol=1e-6)
    assert np.allclose(s.image(5), whole[5], atol=0.5 / 255 + 1e-7)
