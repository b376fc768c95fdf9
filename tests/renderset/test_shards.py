"""`sasmi render --format wds`: WebDataset tar shards that webdataset reads, resumable per shard."""
from __future__ import annotations

import io
import json
import tarfile

import numpy as np
import pytest
from PIL import Image

from sasmi.cli.main import main

from conftest import REPO

PRESET = str(REPO / "scenes" / "muscle_paper.toml")
PARTS = ["png", "mask.png", "instances.png", "shadows.png", "json"]


def render_wds(out, count, *extra):
    return main(["render", PRESET, "--out", str(out), "--count", str(count), "--size", "32", "--spp", "4",
                 "--format", "wds", "--per-shard", "3", *extra])


def members(tar_path):
    with tarfile.open(tar_path) as tar:
        return {m.name: tar.extractfile(m).read() for m in tar}


def assert_same_samples(a: dict, b: dict):
    """Members of two shards: same names, same labels and masks, images within one gray level."""
    assert list(a) == list(b)
    for name in a:
        if name.endswith(".png") and name.count(".") == 1:
            x, y = (np.asarray(Image.open(io.BytesIO(d)), dtype=int) for d in (a[name], b[name]))
            assert np.abs(x - y).max() <= 1, name
        else:
            assert a[name] == b[name], name


@pytest.fixture(scope="module")
def wds_set(tmp_path_factory):
    out = tmp_path_factory.mktemp("wds") / "set"
    assert render_wds(out, 7) == 0
    return out


def test_webdataset_reads_every_sample(wds_set, render_set):
    import webdataset as wds

    run = json.loads((wds_set / "run.json").read_text())
    assert run["shards"] == "shards/shard-{000000..000002}.tar" and run["per_shard"] == 3
    samples = list(wds.WebDataset(str(wds_set / run["shards"]), shardshuffle=False))
    assert [s["__key__"] for s in samples] == [f"{i:06d}" for i in range(7)]
    reference = (render_set / "labels.jsonl").read_text().splitlines()
    for i, sample in enumerate(samples):
        assert set(PARTS) <= set(sample)
        label, expected = json.loads(sample["json"]), json.loads(reference[i])
        assert (label.pop("image"), label.pop("mask")) == (f"{i:06d}.png", f"{i:06d}.mask.png")
        expected.pop("image"), expected.pop("mask")
        assert label == expected
        for part, folder in zip(PARTS[:4], ("images", "masks", "instances", "shadows")):
            got = np.asarray(Image.open(io.BytesIO(sample[part])), dtype=int)
            want = np.asarray(Image.open(render_set / folder / f"{i:06d}.png"), dtype=int)
            assert np.abs(got - want).max() <= (1 if part == "png" else 0), f"{i} {part}"


def test_resume_rewrites_only_missing_or_short_shards(tmp_path, wds_set):
    out = tmp_path / "resumed"
    assert render_wds(out, 7) == 0
    shards = out / "shards"
    kept = {k: (shards / f"shard-{k:06d}.tar").stat().st_mtime_ns for k in (0, 2)}
    (shards / "shard-000001.tar").unlink()
    (shards / ".shard-000001.abc").mkdir()  # temp folder of a killed writer
    (shards / ".shard-000001.abc" / "x.png").write_bytes(b"half")
    assert render_wds(out, 7) == 0
    assert {k: (shards / f"shard-{k:06d}.tar").stat().st_mtime_ns for k in kept} == kept
    assert_same_samples(members(shards / "shard-000001.tar"), members(wds_set / "shards" / "shard-000001.tar"))
    assert sorted(p.name for p in shards.iterdir()) == [f"shard-{k:06d}.tar" for k in range(3)]

    assert render_wds(out, 8) == 0  # a grown count refills the short last shard
    last = members(shards / "shard-000002.tar")
    assert [n for n in last if n.endswith(".json")] == ["000006.json", "000007.json"]
    assert (shards / "shard-000000.tar").stat().st_mtime_ns == kept[0]


def test_shard_flag_splits_tar_shards(tmp_path, wds_set):
    out = tmp_path / "split"
    assert render_wds(out, 7, "--shard", "1/2") == 0
    assert sorted(p.name for p in (out / "shards").iterdir()) == ["shard-000001.tar"]
    assert render_wds(out, 7, "--shard", "0/2") == 0
    for k in range(3):
        name = f"shard-{k:06d}.tar"
        assert_same_samples(members(out / "shards" / name), members(wds_set / "shards" / name))
    assert "shards" in json.loads((out / "run.json").read_text())


def test_read_shard_images_for_training(wds_set, render_set):
    from sasmi.images import read_gray
    from sasmi.renderset.shards import read_shard_images

    images = read_shard_images(wds_set, 16)
    assert len(images) == 7 and all(tuple(x.shape) == (1, 16, 16) for x in images)
    assert all(0.0 <= float(x.min()) and float(x.max()) <= 1.0 for x in images)
    from sasmi.preprocess import resize_short_side

    want = resize_short_side(read_gray(render_set / "images" / "000003.png"), 16)
    assert float((images[3] - want).abs().max()) <= 1.5 / 255


def test_read_shards_with_masks(wds_set, render_set):
    from sasmi.renderset.shards import has_shards, read_shards

    assert has_shards(wds_set) and not has_shards(render_set)
    images, masks = read_shards(wds_set, 32, masks=True)
    for i in (0, 6):
        want = np.asarray(Image.open(render_set / "masks" / f"{i:06d}.png"))
        assert masks[i].shape == (1, 32, 32) and np.array_equal(masks[i][0].numpy(), want)


def test_broken_shard_is_one_error(tmp_path):
    from sasmi.errors import SasmiError
    from sasmi.renderset.shards import read_shard_images

    (tmp_path / "shards").mkdir()
    (tmp_path / "shards" / "shard-000000.tar").write_bytes(b"not a tar" * 100)
    with pytest.raises(SasmiError, match="unreadable shard"):
        read_shard_images(tmp_path, 16)


def test_sasgan_trains_on_a_shard_set(tmp_path):
    """`sasmi train sasgan --renders` takes a `--format wds` render set, masks included."""
    from sasmi.gan.data import ImageSet

    out = tmp_path / "wds"
    assert main(["render", str(PRESET), "--out", str(out), "--count", "3", "--size", "32", "--spp", "2",
                 "--format", "wds", "--per-shard", "2"]) == 0
    images = ImageSet(out, 32, masks=True)
    assert len(images) == 3 and images.masks[0].shape == (1, 32, 32)
    assert set(images.masks[0].unique().tolist()) <= {0, 1, 2}
    assert [p.suffix for p in images.paths] == [".tar", ".tar"]
