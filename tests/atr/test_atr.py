"""ATR-ready data: torch datasets, COCO/YOLO export checked with pycocotools, atr-bench on a toy problem."""
from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from sasmi.cli.main import main
from sasmi.images import write_gray


def test_render_set_dataset_matches_masks_and_labels(render_set):
    from sasmi.atr.datasets import RenderSet
    from sasmi.masks import read_mask

    data = RenderSet(render_set)
    assert len(data) == 8 and data.categories[:2] == ["cylinder", "sphere"]
    image, target = data[0]
    assert image.shape == (1, 32, 32) and image.dtype == torch.float32 and 0 <= image.min() <= image.max() <= 1
    n = len(target["boxes"])
    assert n >= 1 and target["boxes"].shape == (n, 4) and target["labels"].dtype == torch.int64
    assert target["masks"].shape == (n, 32, 32) and target["masks"].dtype == torch.uint8
    classes = read_mask(render_set / "masks" / "000000.png")
    # every instance mask lies inside the class mask's target pixels, and together they cover them
    union = target["masks"].sum(0).numpy()
    assert union.max() == 1 and np.array_equal(union > 0, classes == 1)
    assert np.array_equal(target["shadow_masks"].sum(0).numpy() > 0, classes == 2)
    for box, mask in zip(target["boxes"].tolist(), target["masks"].numpy()):
        rows, cols = np.nonzero(mask)
        assert box == [cols.min(), rows.min(), cols.max() + 1, rows.max() + 1]  # xyxy, end exclusive


def test_render_set_works_with_dataloader_workers(render_set):
    from sasmi.atr.datasets import RenderSet, detection_collate

    loader = torch.utils.data.DataLoader(RenderSet(render_set), batch_size=4, num_workers=2,
                                         collate_fn=detection_collate)
    batches = list(loader)
    assert len(batches) == 2 and all(len(images) == 4 for images, _ in batches)


def test_real_chips_classes_from_subfolders(tmp_path):
    from sasmi.atr.datasets import RealChips

    for sub, value in (("seafloor", 0.2), ("targets", 0.8)):
        for i in range(3):
            write_gray(tmp_path / sub / f"{i}.png", np.full((20, 24), value, np.float32))
    chips = RealChips(tmp_path, size=16)
    assert chips.classes == ["seafloor", "targets"] and len(chips) == 6
    loader = torch.utils.data.DataLoader(chips, batch_size=6, num_workers=2)
    images, labels = next(iter(loader))
    assert images.shape == (6, 1, 16, 16)
    assert torch.allclose(images[labels == 1].mean(), torch.tensor(0.8), atol=0.01)


def test_coco_export_loads_in_pycocotools_and_matches_instance_masks(render_set, tmp_path):
    from pycocotools.coco import COCO

    from sasmi.atr.datasets import RenderSet

    out = tmp_path / "coco.json"
    assert main(["export", str(render_set), "--format", "coco", "--out", str(out)]) == 0
    coco = COCO(str(out))
    data = RenderSet(render_set)
    assert sorted(coco.getImgIds()) == list(range(8))
    assert [c["name"] for c in coco.loadCats(coco.getCatIds())] == data.categories
    for i in range(len(data)):
        _, target = data[i]
        anns = coco.loadAnns(coco.getAnnIds(imgIds=[int(target["image_id"])]))
        assert len(anns) == len(target["boxes"])
        for ann, mask, box, label in zip(anns, target["masks"].numpy(), target["boxes"].tolist(),
                                         target["labels"].tolist()):
            assert np.array_equal(coco.annToMask(ann), mask)
            assert ann["area"] == mask.sum() and ann["category_id"] == label
            x, y, w, h = ann["bbox"]
            assert [x, y, x + w, y + h] == box


def test_yolo_export_layout(render_set, tmp_path):
    from sasmi.atr.datasets import RenderSet

    out = tmp_path / "yolo"
    assert main(["export", str(render_set), "--format", "yolo", "--out", str(out)]) == 0
    data_yaml = (out / "data.yaml").read_text()
    assert "train: images/train" in data_yaml and "val: images/val" in data_yaml and "0: cylinder" in data_yaml
    assert len(list((out / "images" / "train").glob("*.png"))) == 8  # index 9 would be the first in val
    _, target = RenderSet(render_set)[0]
    rows = [line.split() for line in (out / "labels" / "train" / "000000.txt").read_text().splitlines()]
    assert len(rows) == len(target["boxes"])
    x0, y0, x1, y1 = target["boxes"][0].tolist()
    cls, cx, cy, w, h = rows[0]
    assert int(cls) == int(target["labels"][0]) - 1
    assert [float(cx), float(cy), float(w), float(h)] == pytest.approx(
        [(x0 + x1) / 64, (y0 + y1) / 64, (x1 - x0) / 32, (y1 - y0) / 32], abs=1e-5)


def _toy_chips(folder, n, rng, target: bool):
    for i in range(n):
        image = rng.gamma(4.0, 0.25 / 4.0, (32, 32)).astype(np.float32)
        if target:  # a bright highlight with a dark shadow to its right, as the real chips
            r, c = rng.integers(10, 18, 2)
            image[r:r + 4, c:c + 3] = 0.9
            image[r:r + 4, c + 3:c + 10] = 0.02
        write_gray(folder / f"{i}.png", image)


def test_atr_bench_learns_a_separable_toy_and_writes_its_report(tmp_path):
    rng = np.random.default_rng(0)
    for split, n in (("train", 12), ("test", 10)):
        _toy_chips(tmp_path / split / "targets", n, rng, True)
        _toy_chips(tmp_path / split / "seafloor", n, rng, False)
    _toy_chips(tmp_path / "syn" / "targets", 12, rng, True)
    out = tmp_path / "bench"
    assert main(["atr-bench", "--real-train", str(tmp_path / "train"), "--real-test", str(tmp_path / "test"),
                 "--synthetic", str(tmp_path / "syn"), "--out", str(out), "--seeds", "2", "--size", "32",
                 "--steps", "60", "--real-per-class", "4", "all"]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert set(metrics["results"]) == {"4", "all"}
    for regimes in metrics["results"].values():
        assert set(regimes) == {"real", "real+synthetic", "synthetic"}
        for m in regimes.values():
            assert len(m["auc"]["values"]) == 2
    assert metrics["results"]["all"]["real"]["auc"]["mean"] > 0.9  # the toy is easy: a broken loop fails here
    assert (out / "atr_bench.png").is_file() and "real+synthetic" in (out / "table.md").read_text()


def test_atr_bench_bad_input_is_one_line(tmp_path, capsys):
    assert main(["atr-bench", "--real-train", str(tmp_path / "nope"), "--real-test", str(tmp_path),
                 "--synthetic", str(tmp_path), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--real-train" in err[0] and not (tmp_path / "o").exists()


def test_a_mesh_keeps_its_class_id_in_every_set_of_one_preset(tmp_path):
    """Class ids come from the preset's meshes, not from those a set happened to draw: a train set and a
    test set rendered apart must agree, or a detector's classes are swapped between them."""
    import trimesh

    from sasmi.atr.datasets import RenderSet
    from sasmi.renderset.write import RenderJob, render_set
    from sasmi.scene.preset import load_preset

    for name, extents in (("cube_a", [0.8, 0.8, 0.8]), ("drum_b", [1.6, 0.6, 0.5])):
        trimesh.creation.box(extents=extents).export(tmp_path / f"{name}.obj")
    kinds = "".join(f'[[targets]]\nshape = "mesh"\nmesh = "{name}.obj"\nweight = 1\n' for name in ("cube_a", "drum_b"))
    (tmp_path / "p.toml").write_text(f"targets_per_chip = 1\n[sonar]\nchip_size = 12.0\n{kinds}")
    preset = load_preset(tmp_path / "p.toml")
    drawn = [preset.sample(0, i).targets[0].mesh.endswith("drum_b.obj") for i in range(12)]
    both = drawn.index(not drawn[0]) + 1  # chips 0 .. both - 1 hold both meshes; chip 0 alone one of them
    one = render_set(RenderJob(preset=preset, out=tmp_path / "one", count=1, size=32, spp=2), progress=False)
    two = render_set(RenderJob(preset=preset, out=tmp_path / "two", count=both, size=32, spp=2), progress=False)
    assert RenderSet(one).categories == RenderSet(two).categories
    assert RenderSet(one).categories[-2:] == ["cube_a", "drum_b"]
