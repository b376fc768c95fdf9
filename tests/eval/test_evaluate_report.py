"""`sasmi evaluate` end to end: a tiny trained φ run, synthetic sets with known answers,
target preservation, pose sweeps, and bad input."""
import json
import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import torch

from sasmi.gan.kinds.autoencoder import AUTOENCODER, AutoencoderRun
from sasmi.gan.kinds.sasgan import SASGAN, SasganRun
from sasmi.gan.loop import train
from sasmi.gan.autoencoder import AutoencoderConfig, load_encoder
from sasmi.cli import main as cli
from sasmi.eval import features, phi_fid, preservation, sweeps
from sasmi.eval.cache import encoder_fingerprint
from sasmi.errors import SasmiError
from sasmi.images import list_images, read_gray, write_gray
from sasmi.masks import write_class_mask
from sasmi.labels import TargetLabel
from sasmi.scene.model import Scene, Sonar, Target

CPU = torch.device("cpu")
TINY_AE = AutoencoderRun(steps=3, size=32, batch=4, autoencoder=AutoencoderConfig((8, 8, 8, 16)),
                               log_every=1, sample_every=10, checkpoint_every=10)
SIZE = 48  # written at 48 px, read at the encoder's 32: the resize path is exercised too


def chip(rng, col: float, row: float, speckle: bool = True, target: bool = True):
    """(image, mask, label): a 4×5 px bright target centred at (col, row), its 12 px shadow to the right."""
    image = 0.35 * (rng.gamma(4.0, 0.25, (SIZE, SIZE)) if speckle else 1.0 + 0.05 * rng.standard_normal((SIZE, SIZE)))
    mask = np.zeros((SIZE, SIZE), np.uint8)
    c0, r0 = int(col - 1.5), int(row - 2)
    if target:
        mask[r0:r0 + 5, c0 + 4:c0 + 16] = 2
        mask[r0:r0 + 5, c0:c0 + 4] = 1
        image[mask == 2] *= 0.1
        image[mask == 1] = 0.95
    label = {"x": 0.0, "y": 0.0, "yaw": 0.0, "burial": 0.0, "pixel_centre": [c0 + 1.5, r0 + 2.0],
             "bbox": [c0, r0, c0 + 4, r0 + 5], "shadow_bbox": [c0 + 4, r0, c0 + 16, r0 + 5]}
    return np.clip(image, 0, 1), mask, label


def write_set(folder: Path, n: int, seed: int, labelled: bool = False, shift: int = 0, **kw) -> Path:
    """A plain folder of chips, or a render set (images/, masks/, labels.jsonl); `shift` moves
    the image content right by that many px but not its mask and labels (a translation that
    misplaces the target)."""
    rng = np.random.default_rng(seed)
    lines = []
    for i in range(n):
        image, mask, label = chip(rng, rng.uniform(12, 20), rng.uniform(14, 34), **kw)
        image = np.roll(image, shift, axis=1)
        write_gray(folder / ("images" if labelled else "") / f"{i:06d}.png", image)
        if labelled:
            write_class_mask(folder / "masks" / f"{i:06d}.png", mask)
            lines.append(json.dumps({"index": i, "targets": [label], "size": SIZE}))
    if labelled:
        (folder / "labels.jsonl").write_text("\n".join(lines) + "\n")
    return folder


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    root = tmp_path_factory.mktemp("evaluate")
    d = SimpleNamespace(
        root=root,
        real=write_set(root / "real", 24, seed=0),
        renders=write_set(root / "renders", 12, seed=1, labelled=True, speckle=False),
        shifted=write_set(root / "shifted", 12, seed=2, labelled=True, shift=5),
        floor=write_set(root / "floor", 12, seed=3, target=False),
    )
    d.phi = train(AUTOENCODER, TINY_AE, root / "ae", {"real": d.real}, CPU).out
    return d


def evaluate_cli(capsys, *args) -> tuple[int, str]:
    rc = cli.main(["evaluate", *map(str, args)])
    return rc, capsys.readouterr().err


def test_without_phi_the_shipped_one_measures_and_is_named(data, capsys):
    from sasmi.weights import shipped

    out = data.root / "shipped"
    rc, err = evaluate_cli(capsys, "--real", data.real, "--set", f"shifted={data.shifted}", "--out", out,
                           "--bootstrap", 5, "--no-two-sample", "--no-cache")
    assert rc == 0, err
    named = f"the shipped φ (phi.pt), weights {encoder_fingerprint(load_encoder(shipped('phi')))[:12]}"
    assert f"measured in φ: {named}" in err and f"- phi: `{named}`" in (out / "report.md").read_text()
    fid = json.loads((out / "metrics.json").read_text())["realism"]["shifted"]["fid"]
    assert phi_fid(data.real, data.shifted) == pytest.approx(fid, rel=0.2)  # the same φ, one call


def test_report_from_a_trained_run(data, capsys):
    out = data.root / "report"
    rc, err = evaluate_cli(capsys, "--real", data.real, "--set", f"renders={data.renders}",
                           "--set", f"shifted={data.shifted}", "--set", f"floor={data.floor}",
                           "--phi", data.phi, "--out", out, "--bootstrap", 10, "--device", "cpu",
                           "--cache", data.root / "cache")
    assert rc == 0, err
    assert [p.name.split("-")[0] for p in (data.root / "cache").iterdir()] == ["real"]  # only the real φ is kept
    assert "fewer than φ's 1024 dimensions" in err  # 24 real images < 1024 φ dimensions
    # without a terminal (no progress bars) each stage still says one line
    stages = [line.split("] ", 1)[1] for line in err.splitlines() if line.startswith("sasmi evaluate: [")]
    encoder = load_encoder(data.phi)
    assert stages[-2] == f"measured in φ: {encoder.checkpoint}, weights {encoder_fingerprint(encoder)[:12]}"
    assert [s.split(":")[0] for s in stages] == ["φ of real", "φ of renders", "φ of shifted", "φ of floor", "realism",
                                                 "coverage", "copying detector", "t-SNE", "two-sample test",
                                                 "target preservation", "image statistics", "measured in φ",
                                                 f"wrote {out}/report.md"]

    m = json.loads((out / "metrics.json").read_text())
    assert list(m["realism"]) == ["real→real", "renders", "shifted", "floor"]
    assert list(m["two_sample"]) == ["renders", "shifted", "floor"] and (out / "most_synthetic.png").is_file()
    assert all(0 <= s["auc"] <= 1 and len(s["most_synthetic"]) >= 1 for s in m["two_sample"].values())
    assert "Two-sample test" in (out / "report.md").read_text()
    for name, row in m["realism"].items():
        assert row["fid"] >= 0 and row["fid_std"] > 0, name
        assert 0 <= row["precision"] <= 1 and 0 <= row["recall"] <= 1, name
        assert math.isfinite(row["kid"]) and row["kid_std"] > 0, name
        assert 0 <= row["fid_mean_part"] <= row["fid"] * 1.5, name  # real→real: one split against the splits' mean
        assert math.isfinite(row["gray_levels"]), name
    # "shifted" has the real chips' texture and targets; floor lacks targets, renders lack speckle
    r = m["realism"]
    for worse in ("floor", "renders"):
        assert r[worse]["fid_ratio"] > r["shifted"]["fid_ratio"] and r[worse]["kid"] > r["shifted"]["kid"], worse
    # "shifted" keeps the real chips' gray levels; the flat renders' levels are far from them
    assert r["renders"]["gray_levels"] > 5 * max(r["shifted"]["gray_levels"], r["real→real"]["gray_levels"], 0.01)
    assert set(m["copying"]) == {"renders", "shifted", "floor"}
    # coverage: its mean is the recall; the floors without targets leave more real chips uncovered
    for name, c in m["coverage"].items():
        assert abs(c["mean"] - r[name]["recall"]) < 0.25 and len(c["least"]) == 6, name
    assert all(x["chip"].endswith(".png") and x["nearest"].endswith(".png") for x in m["coverage"]["floor"]["least"])
    assert m["coverage"]["floor"]["mean"] < m["coverage"]["shifted"]["mean"]
    assert set(m["copying"]["floor"]) == {"pixel", "phi"}
    assert any("fewer than" in w for w in m["warnings"])

    # target preservation: the renders keep their labels; the 5 px shift shows as ≈ 5 px
    tp = m["target_preservation"]
    assert set(tp) == {"renders", "shifted"}  # floor has no masks/labels
    assert tp["renders"]["centroid_error_px"] < 1.0 and tp["renders"]["shadow_iou"] > 0.6
    assert tp["shifted"]["centroid_error_px"] == pytest.approx(5.0, abs=1.0)
    assert tp["shifted"]["shadow_iou"] < 0.6 * tp["renders"]["shadow_iou"]
    assert m["pose_sweep"] == {"skipped": "no --preset and --generator given"}

    report = (out / "report.md").read_text()
    for text in ("## Realism in φ space", "| real→real | 12 + 12 |", "| renders | 12 |", "## Coverage", "## Copying detector",
                 "## t-SNE of φ", "## Target preservation", "Skipped (no masks/ and labels.jsonl): floor",
                 "## Pose sweeps", "Skipped: no --preset"):
        assert text in report, text
    for figure in ("tsne.png", "least_covered.png", "nearest_distances.png", "neighbours_renders.png", "neighbours_floor.png",
                   "preservation_renders.png", "preservation_shifted.png"):
        assert (out / figure).stat().st_size > 1000, figure
        assert f"]({figure})" in report, figure


def test_phi_features_from_paths_and_arrays_agree(data):
    encoder = load_encoder(data.phi)
    paths = list_images(data.real)[:5]
    from_paths = features.phi_features(encoder, paths, batch=2)
    from_arrays = features.phi_features(encoder, np.stack([read_gray(p) for p in paths]), batch=3)
    assert from_paths.shape == (5, 1024) and from_paths.dtype == np.float64
    np.testing.assert_allclose(from_paths, from_arrays, rtol=1e-5, atol=1e-6)
    assert phi_fid(data.real, data.real, phi=encoder) == pytest.approx(0.0, abs=1e-9)
    assert phi_fid(data.real, data.real, phi=data.phi) == pytest.approx(0.0, abs=1e-9)  # a run folder


@pytest.mark.parametrize("case", ["missing real", "no equals", "empty name", "missing set dir", "twice", "reserved",
                                  "preset alone", "phi not a folder", "phi not a run", "too few real"])
def test_bad_input_exits_2_with_one_line(data, capsys, case):
    good = {"--real": data.real, "--set": f"a={data.floor}", "--phi": data.phi, "--out": data.root / "bad"}
    extra = []
    if case == "missing real":
        good["--real"] = data.root / "nope"
    elif case == "no equals":
        good["--set"] = str(data.floor)
    elif case == "empty name":
        good["--set"] = f"={data.floor}"
    elif case == "missing set dir":
        good["--set"] = f"a={data.root / 'nope'}"
    elif case == "twice":
        extra = ["--set", f"a={data.renders}"]
    elif case == "reserved":
        good["--set"] = f"real={data.floor}"
    elif case == "preset alone":
        extra = ["--preset", "scenes/muscle_paper.toml"]
    elif case == "phi not a folder":
        good["--phi"] = data.root / "nope"
    elif case == "phi not a run":
        good["--phi"] = data.floor
    elif case == "too few real":
        good["--real"] = write_set(data.root / "three", 3, seed=9)
    rc, err = evaluate_cli(capsys, *[str(v) for kv in good.items() for v in kv], *extra)
    assert rc == 2
    assert err.startswith("sasmi evaluate: error: ") and err.count("\n") == 1, err


def test_measure_image_known_answers():
    rng = np.random.default_rng(0)
    image, mask, label = chip(rng, 20.0, 24.0)
    label = TargetLabel.from_json(label)
    m = preservation.measure_image(image, mask, [label])
    assert m["shadow_iou"] > 0.7 and m["centroid_errors"][0] < 0.7 and m["target_contrast"] > 1.5
    shifted = preservation.measure_image(np.roll(image, (3, 4), axis=(0, 1)), mask, [label])
    assert shifted["centroid_errors"][0] == pytest.approx(5.0, abs=0.7)
    erased = preservation.measure_image(chip(rng, 20.0, 24.0, target=False)[0], mask, [label])
    assert erased["shadow_iou"] < 0.1 and erased["target_contrast"] < 1.3
    s = preservation.summarise([m, erased])
    assert s["images"] == 2 and s["targets"] == 2


def test_preservation_of_a_resized_translation(tmp_path):
    # a translation written at twice the render size: masks and labels are rescaled to it
    small = write_set(tmp_path / "small", 4, seed=5, labelled=True)
    big = tmp_path / "big"
    for path in sorted((small / "images").iterdir()):
        image = read_gray(path)
        write_gray(big / "images" / path.name, np.kron(image, np.ones((2, 2))))
    (big / "masks").symlink_to(small / "masks")
    (big / "labels.jsonl").symlink_to(small / "labels.jsonl")
    report = preservation.target_preservation({"small": small, "big": big}, tmp_path / "out")
    tp = report.metrics["target_preservation"]
    assert tp["big"]["centroid_error_px"] < 1.5 and tp["big"]["shadow_iou"] > 0.7
    assert tp["small"]["centroid_error_px"] < 1.0


class FakeRender:
    """Stand-in renderer at 48 px: a 4×5 px target at the scene's first target, its shadow to the right."""

    def __call__(self, scene):
        half = scene.sonar.chip_size / 2
        t = scene.targets[0]
        col, row = ((t.x + half) / scene.sonar.chip_size * SIZE - 0.5, (t.y + half) / scene.sonar.chip_size * SIZE - 0.5)
        image, mask, label = chip(np.random.default_rng(int(t.yaw)), col, row)
        return SimpleNamespace(image=image.astype(np.float32), mask=mask, labels={"targets": [label]})


def test_pose_sweep_with_stand_in_renderer(tmp_path):
    scene = Scene(sonar=Sonar(chip_size=6.0), targets=(Target(x=-1.0, yaw=30.0), Target(x=1.0)))
    cfg = sweeps.SweepConfig(steps=4)
    moved, turned = sweeps.pose_scenes(scene, cfg)
    assert [len(s.targets) for s in moved + turned] == [1] * 8
    assert [t.targets[0].x for t in moved] == pytest.approx([-1.5, -0.5, 0.5, 1.5])
    assert [t.targets[0].y for t in moved] == pytest.approx([-1.5, -0.5, 0.5, 1.5])
    assert [t.targets[0].yaw for t in turned] == pytest.approx([0, 60, 120, 180])

    kept = sweeps.pose_sweep(scene, FakeRender(), lambda images: images, tmp_path, cfg).metrics["pose_sweep"]
    moved_out = sweeps.pose_sweep(scene, FakeRender(), lambda images: np.roll(images, 4, axis=2), tmp_path / "shift",
                                  cfg).metrics["pose_sweep"]
    assert [p["x"] for p in kept["translation"]] == pytest.approx([-1.5, -0.5, 0.5, 1.5])
    assert [p["yaw"] for p in kept["rotation"]] == pytest.approx([0, 60, 120, 180])
    for pose, shifted in zip(kept["translation"] + kept["rotation"], moved_out["translation"] + moved_out["rotation"]):
        # the render's numbers come from the render alone (whatever the translation does), and
        # the stand-in puts its target where its label says
        assert shifted["render"] == pose["render"]
        assert pose["render"]["centroid_error_px"] < 1.0 and pose["render"]["shadow_iou"] > 0.5
        assert pose["translated"] == pose["render"]  # identity translation keeps every number
        assert shifted["translated"]["centroid_error_px"] == pytest.approx(4.0, abs=0.7)
        assert shifted["translated"]["shadow_iou"] < 0.7 * pose["render"]["shadow_iou"]
    assert (tmp_path / "sweep_translation.png").is_file() and (tmp_path / "sweep_rotation.png").is_file()


def test_pose_sweep_needs_a_target():
    with pytest.raises(SasmiError, match="no target"):
        sweeps.pose_scenes(Scene())


def test_preservation_on_the_renderer_output(render_set, tmp_path):
    # the label conventions (pixel_centre, bbox, mask values) as the real renderer writes them
    tp = preservation.target_preservation({"renders": render_set}, tmp_path).metrics["target_preservation"]["renders"]
    assert tp["images"] == 8 and tp["lost"] < 0.25
    assert tp["centroid_error_px"] < 4.0 and tp["shadow_iou"] > 0.4


@pytest.mark.slow
def test_pose_sweep_through_mitsuba_and_a_trained_generator(data, tmp_path):
    from sasmi.gan.critic import CriticConfig
    from sasmi.gan.generator import GeneratorConfig

    cfg = SasganRun(steps=1, size=32, batch=2, n_critic=1, generator=GeneratorConfig(4, 1),
                          critic=CriticConfig(4), log_every=1, sample_every=10, checkpoint_every=10)
    generator = train(SASGAN, cfg, tmp_path / "gan", {"real": data.real, "renders": data.renders, "phi": data.phi}, CPU).out
    preset = Path(__file__).resolve().parents[2] / "scenes" / "muscle_paper.toml"
    report = sweeps.pose_sweep_from_runs(preset, generator, tmp_path, sweeps.SweepConfig(steps=3, spp=4))
    sweep = report.metrics["pose_sweep"]
    assert len(sweep["translation"]) == 3 and len(sweep["rotation"]) == 3
    assert all(p["render"]["centroid_error_px"] < 4.0 for p in sweep["translation"])
    assert (tmp_path / "sweep_rotation.png").is_file()


def test_an_evaluation_stopped_in_a_stage_goes_on_from_it_and_writes_the_unbroken_report(data, capsys, monkeypatch):
    import sasmi.eval.evaluate as evaluation

    args = ["--real", data.real, "--set", f"renders={data.renders}", "--set", f"shifted={data.shifted}",
            "--phi", data.phi, "--bootstrap", 5, "--no-cache"]
    unbroken, stopped = data.root / "unbroken", data.root / "stopped"
    assert evaluate_cli(capsys, *args, "--out", unbroken)[0] == 0
    copying = evaluation.copying_metrics

    def interrupted(*a, **k):
        raise KeyboardInterrupt  # Ctrl-C in the copying detector, after realism and coverage

    def again(*a, **k):
        raise AssertionError("a finished stage computed again")

    monkeypatch.setattr(evaluation, "copying_metrics", interrupted)
    rc, err = evaluate_cli(capsys, *args, "--out", stopped)
    assert rc == 130 and "rerun the same command to continue" in err and not (stopped / "report.md").exists()
    monkeypatch.setattr(evaluation, "copying_metrics", copying)
    monkeypatch.setattr(evaluation, "realism_table", again)
    monkeypatch.setattr(evaluation, "coverage_metrics", again)
    rc, err = evaluate_cli(capsys, *args, "--out", stopped)
    assert rc == 0 and "coverage: the real chips each set covers least: kept from the stopped run" in err, err
    assert (stopped / "metrics.json").read_text() == (unbroken / "metrics.json").read_text()
    assert (stopped / "report.md").read_text() == (unbroken / "report.md").read_text()
    assert not (stopped / ".stages").exists()  # the report written, nothing kept behind
