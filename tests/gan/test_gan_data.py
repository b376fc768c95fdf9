"""Image folders → batches: formats, recursion, skipping, augmentation, resumable order."""
import numpy as np
import pytest
import tifffile
import torch
from PIL import Image

from sasmi.gan.data import Batches, ImageSet
from sasmi.errors import SasmiError


def _png(path, a01):
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(np.round(a01 * 255).astype(np.uint8), mode="L").save(path)


@pytest.fixture
def mixed_folder(tmp_path):
    """Five readable images in nested folders and four formats, plus one broken file."""
    ramp = np.tile(np.linspace(0, 1, 40, dtype=np.float32), (40, 1))  # brightness grows with x (range)
    _png(tmp_path / "targets" / "a.png", ramp)
    _png(tmp_path / "seafloor" / "deep" / "b.png", ramp[:, :32][:32])
    Image.fromarray(np.round(ramp * 255).astype(np.uint8), mode="L").save(tmp_path / "c.jpg")
    tifffile.imwrite(tmp_path / "d.tiff", np.round(ramp * 65535).astype(np.uint16))
    np.save(tmp_path / "e.npy", np.tile(np.linspace(0, 1, 64, dtype=np.float32), (48, 1)))  # not square
    (tmp_path / "broken.png").write_bytes(b"not a png")
    return tmp_path


def test_reads_formats_recursively_and_skips_unreadable(mixed_folder):
    with pytest.warns(UserWarning, match="broken.png"):
        images = ImageSet(mixed_folder, 32)
    assert len(images) == 5
    assert {p.name for p in images.paths} == {"a.png", "b.png", "c.jpg", "d.tiff", "e.npy"}
    assert all(min(im.shape[1:]) == 32 for im in images.images)
    assert images.images[images.paths.index(mixed_folder / "e.npy")].shape == (1, 32, 43)


def test_worker_processes_read_the_same_set_in_the_same_order(mixed_folder, monkeypatch):
    from sasmi.gan import data

    with pytest.warns(UserWarning, match="broken.png"):
        alone = ImageSet(mixed_folder, 32)
    monkeypatch.setattr(data, "reading_workers", lambda n: 2)
    with pytest.warns(UserWarning, match="broken.png"):  # a worker's failure is still named, and skipped
        workers = ImageSet(mixed_folder, 32)
    assert workers.paths == alone.paths
    assert all(torch.equal(a, b) for a, b in zip(workers.images, alone.images))


def test_batches_are_in_range_and_flip_along_track_only(mixed_folder):
    with pytest.warns(UserWarning):
        images = ImageSet(mixed_folder, 32)
    batches = Batches(images, batch=4, seed=0)
    for _ in range(10):
        x = batches.next()
        assert x.shape == (4, 1, 32, 32) and x.min() >= -1 and x.max() <= 1
        # range (x) profiles stay increasing: no left-right flip ever
        assert (x.mean(dim=(1, 2)).diff(dim=1) >= -1e-3).all()


def test_flips_happen_along_track(tmp_path):
    image = np.zeros((32, 32), np.float32)
    image[:4] = 1  # a bright top edge
    _png(tmp_path / "top.png", image)
    x = Batches(ImageSet(tmp_path, 32), batch=64, seed=0).next()
    top_bright = x[:, 0, 0].mean(dim=1) > 0
    assert 0 < top_bright.sum() < 64  # some flipped upside-down, some not


def test_batch_stream_resumes_exactly(mixed_folder):
    with pytest.warns(UserWarning):
        images = ImageSet(mixed_folder, 32)
    a = Batches(images, batch=3, seed=5)
    for _ in range(4):
        a.next()
    state = a.state_dict()
    expected = [a.next() for _ in range(5)]
    b = Batches(images, batch=3, seed=99)
    b.load_state_dict(state)
    assert all(torch.equal(e, b.next()) for e in expected)


def test_empty_or_unusable_folder_is_one_error(tmp_path):
    with pytest.raises(SasmiError, match="no readable image"):
        ImageSet(tmp_path, 32)
    (tmp_path / "x.png").write_bytes(b"broken")
    with pytest.warns(UserWarning), pytest.raises(SasmiError, match="no readable image"):
        ImageSet(tmp_path, 32)
    with pytest.raises(SasmiError, match="not a folder"):
        ImageSet(tmp_path / "missing", 32)
    with pytest.raises(SasmiError, match="multiple of 16"):
        ImageSet(tmp_path, 40)


def test_masks_are_read_as_ids_from_palette_pngs(tmp_path):
    ids = np.zeros((32, 32), np.uint8)
    ids[10:14, 10:14], ids[10:14, 16:24] = 1, 2
    _png(tmp_path / "images" / "000000.png", np.full((32, 32), 0.4))
    (tmp_path / "masks").mkdir()
    palette = Image.fromarray(ids, mode="P")
    palette.putpalette([40, 40, 40, 230, 60, 40, 40, 110, 230] + [0] * 759)  # colours, as sasmi draws them
    palette.save(tmp_path / "masks" / "000000.png")
    images = ImageSet(tmp_path, 16, masks=True)
    assert images.masks[0].shape == (1, 16, 16)
    assert set(images.masks[0].unique().tolist()) == {0, 1, 2}
    x, masks = Batches(images, batch=2, seed=0).next_with_masks()
    assert masks.shape == (2, 1, 16, 16) and masks.dtype == torch.uint8
