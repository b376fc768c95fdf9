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


def _toy_bench(tmp_path, rng):
    for split, n in (("train", 12), ("test", 10)):
        _toy_chips(tmp_path / split / "targets", n, rng, True)
        _toy_chips(tmp_path / split / "seafloor", n, rng, False)
    _toy_chips(tmp_path / "syn" / "targets", 12, rng, True)
    _toy_chips(tmp_path / "syn_floor", 12, rng, False)
    return ["atr-bench", "--real-train", str(tmp_path / "train"), "--real-test", str(tmp_path / "test"),
            "--synthetic", str(tmp_path / "syn"), "--synthetic-negatives", str(tmp_path / "syn_floor"),
            "--seeds", "2", "--size", "32", "--steps", "60", "--real-per-class", "0", "4", "all"]


def test_atr_bench_learns_a_separable_toy_every_way_and_resumes(tmp_path, capsys):
    argv = _toy_bench(tmp_path, np.random.default_rng(0))
    out = tmp_path / "bench"
    assert main([*argv, "--out", str(out)]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert set(metrics["results"]) == {"0", "4", "all"}
    assert set(metrics["results"]["0"]) == {"alone"}  # no real target: only the synthetic targets can be used
    for n in ("4", "all"):
        assert set(metrics["results"][n]) == {"real", "mixed", "alone", "pretrain", "replay"}
    for ways in metrics["results"].values():
        for m in ways.values():
            assert len(m["auc"]["values"]) == 2 and 0.0 <= m["pd"]["mean"] <= 1.0
    assert metrics["results"]["all"]["real"]["auc"]["mean"] > 0.9  # the toy is easy: a broken loop fails here
    assert metrics["results"]["0"]["alone"]["auc"]["mean"] > 0.9  # synthetic targets alike the real ones
    pairs = {(c["n"], c["way"]): c for c in metrics["paired"]}
    assert pairs[("0", "alone")]["against"] == "real at 4" and pairs[("all", "pretrain")]["seeds"] == 2
    assert metrics["counts"]["syn_negatives"] == 12
    assert (out / "atr_bench.png").is_file() and "pretrain" in (out / "table.md").read_text()
    lines = (out / "runs.jsonl").read_text().splitlines()
    assert len(lines) == 1 + 2 * (1 + 5 + 5)  # the settings, then one line per arm and seed
    capsys.readouterr()
    assert main([*argv, "--out", str(out)]) == 0  # a rerun trains nothing: every run is on file
    assert "seed" not in capsys.readouterr().err and (out / "runs.jsonl").read_text().splitlines() == lines
    (out / "runs.jsonl").write_text("\n".join(lines[:-1]) + "\n" + lines[-1][:20])  # killed mid-line
    assert main([*argv, "--out", str(out)]) == 0
    assert capsys.readouterr().err.count("seed") == 1  # the cut run alone is trained again
    assert main([*argv, "--out", str(out)]) == 0 and "seed" not in capsys.readouterr().err  # and kept
    assert main([*argv[:-3], "--steps", "61", "--out", str(out)]) == 2  # other settings into the same folder


def test_negatives_of_another_sonar_are_left_out(tmp_path):
    rng = np.random.default_rng(1)
    argv = _toy_bench(tmp_path, rng)
    for side, n in (("train", 12), ("test", 10)):  # targets and half the seafloor of sonar a, the rest of sonar b
        rows = [f"targets/{i}.png,targets,a_g{i}" for i in range(n)]
        rows += [f"seafloor/{i}.png,seafloor,{'a' if i % 2 else 'b'}_g{i}" for i in range(n)]
        (tmp_path / side / "MANIFEST.csv").write_text("file,category,scene_group\n" + "\n".join(rows) + "\n")
    argv = [*argv[:-3], "all", "--ways", "real"]
    assert main([*argv, "--out", str(tmp_path / "same")]) == 0
    counts = json.loads((tmp_path / "same" / "metrics.json").read_text())["counts"]
    assert counts["train_negatives"] == 6 and counts["test_negatives"] == 5
    assert main([*argv, "--any-sonar", "--out", str(tmp_path / "any")]) == 0
    counts = json.loads((tmp_path / "any" / "metrics.json").read_text())["counts"]
    assert counts["train_negatives"] == 12 and counts["test_negatives"] == 10


def test_paired_differences_see_through_the_spread_between_seeds():
    from sasmi.atr.summary import paired

    rng = np.random.default_rng(0)
    base = rng.uniform(0.6, 0.95, 10)  # seeds differ far more than the effect
    rows = [{"n": "10", "way": "real", "seed": s, "accuracy": b, "auc": b, "pd": b} for s, b in enumerate(base)]
    rows += [{"n": "10", "way": "mixed", "seed": s, "accuracy": b + 0.02, "auc": b + 0.02 + 0.001 * (s % 2),
              "pd": b - 0.01} for s, b in enumerate(base)]
    (c,) = paired(rows, ["10"], 40)
    assert c["auc"]["mean"] == pytest.approx(0.0205) and 0 < c["auc"]["ci95"] < 0.001
    assert c["accuracy"]["mean"] == pytest.approx(0.02) and c["pd"]["mean"] == pytest.approx(-0.01)
    assert c["against"] == "real at 10" and c["seeds"] == 10


def test_pd_is_read_at_the_false_alarm_rate():
    import torch

    from sasmi.atr.bench import score

    class Brightness(torch.nn.Module):  # the chip's mean as its logit
        def forward(self, x):
            return x.mean(dim=(1, 2, 3)) * 5  # unsaturated: no ties at p = 1

    levels = np.linspace(0.1, 0.9, 100, dtype=np.float32)
    negatives = np.stack([np.full((16, 16), v, np.float32) for v in levels])
    targets = np.stack([np.full((16, 16), v, np.float32) for v in levels[::-1] + 0.004])
    m = score(Brightness(), targets, negatives, pfa=0.05)
    assert m["pd"] == pytest.approx(0.05, abs=0.011)  # as bright as the negatives: Pd ≈ Pfa
    assert score(Brightness(), np.full_like(targets[:10], 0.95), negatives, pfa=0.05)["pd"] == 1.0


def test_replayed_chips_fill_half_of_each_class_in_every_batch():
    from sasmi.eval import classifier

    class Recorder(torch.nn.Module):  # remembers the level of each chip it is shown
        def __init__(self):
            super().__init__()
            self.w, self.seen = torch.nn.Parameter(torch.ones(())), []

        def forward(self, x):
            self.seen.append(x.mean(dim=(1, 2, 3)).detach())
            return self.w * x.mean(dim=(1, 2, 3))

    def level(v, n):  # flat chips: flips and shifts leave them as they are
        return np.full((n, 16, 16), v, np.float32)

    model = Recorder()
    classifier.train(level(0.2, 3), level(0.4, 5), steps=3, seed=0, batch=8, model=model,
                     replay=(level(0.6, 7), level(0.8, 9)))
    for batch in model.seen:  # negatives, then targets, as the labels run; in [-1, 1]
        assert batch.tolist() == pytest.approx([-0.2, -0.2, 0.6, 0.6, -0.6, -0.6, 0.2, 0.2])
    with pytest.raises(Exception, match="both classes"):
        classifier.train(level(0.2, 3), level(0.4, 5), steps=1, seed=0, replay=(level(0.6, 2), level(0.8, 0)))


def test_the_command_line_knows_the_bench_ways():
    from sasmi.atr.bench import WAYS
    from sasmi.cli import atr

    assert atr.WAYS == WAYS


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


def test_a_second_bench_in_a_busy_folder_is_refused_in_one_line(tmp_path, capsys):
    from sasmi.images import FolderLock

    out = tmp_path / "bench"
    held = FolderLock(out, "running sasmi atr-bench")  # as another bench would hold it
    capsys.readouterr()
    assert main([*_toy_bench(tmp_path, np.random.default_rng(0)), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "is running sasmi atr-bench in this folder" in err, err
    assert sorted(p.name for p in out.iterdir()) == [".lock"]  # not a run trained
    held.release()
