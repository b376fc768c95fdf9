"""evaluate_folders with a stand-in φ: the image-statistics hook, and target preservation of a labelled real set."""
import numpy as np
import torch

from sasmi.eval.config import EvalConfig
from sasmi.eval.evaluate import evaluate_folders
from sasmi.images import write_gray
from sasmi.masks import write_class_mask
from sasmi.labels import ChipLabel, TargetLabel


class TinyEncoder(torch.nn.Module):
    image_size = 16

    def __init__(self):
        super().__init__()
        torch.manual_seed(0)
        self.conv = torch.nn.Conv2d(1, 1, 4, stride=4)

    def forward(self, x):  # (B, 1, 16, 16) in [-1, 1] → (B, 16)
        return self.conv(x).flatten(1)


def render_set(folder, n, rng):
    """A render set: a bright 3×3 target with its shadow to the right, labelled through sasmi.labels."""
    lines = []
    for i in range(n):
        image, mask = rng.uniform(0.3, 0.5, (16, 16)), np.zeros((16, 16), np.uint8)
        mask[6:9, 4:7], mask[6:9, 7:13] = 1, 2
        image[mask == 1], image[mask == 2] = 0.95, 0.02
        write_gray(folder / "images" / f"{i:06d}.png", image)
        write_class_mask(folder / "masks" / f"{i:06d}.png", mask)
        target = TargetLabel({"shape": "box"}, (5.0, 7.0), (4, 6, 7, 9), (7, 6, 13, 9))
        lines.append(ChipLabel(index=i, size=16, scene={}, targets=(target,)).dumps())
    (folder / "labels.jsonl").write_text("\n".join(lines) + "\n")
    return folder


def test_statistics_hook_and_labelled_real(tmp_path):
    rng = np.random.default_rng(0)
    real = render_set(tmp_path / "real", 10, rng)
    plain = tmp_path / "plain"
    for i in range(6):
        write_gray(plain / f"{i}.png", rng.uniform(0, 1, (16, 16)))
    seen = []

    def stand_in(folder):
        seen.append(folder)
        return {"chips": len(list(folder.rglob("*.png"))), "mean": 0.25}

    cfg = EvalConfig(bootstrap=2, kid_subsets=3, tsne_per_set=8)
    report = evaluate_folders(real, {"plain": plain}, TinyEncoder(), tmp_path / "out", cfg, statistics=stand_in)
    assert seen == [real, plain]
    assert report.metrics["image_statistics"] == {"real": {"chips": 20, "mean": 0.25},
                                                  "plain": {"chips": 6, "mean": 0.25}}
    (section,) = [s for s in report.sections if s.title == "Image statistics"]
    assert "| real | 20 | 0.25 |" in section.body and "| plain | 6 | 0.25 |" in section.body
    assert list(report.metrics["target_preservation"]) == ["real"]  # the real set has masks: measured
    assert report.metrics["target_preservation"]["real"]["centroid_error_px"] < 1.0
    without = evaluate_folders(real, {"plain": plain}, TinyEncoder(), tmp_path / "out2", cfg)
    assert "image_statistics" not in without.metrics
