"""`sasmi generate`: render and translate streamed, with the render's masks and labels."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch
from PIL import Image

from sasmi.gan.autoencoder import AutoencoderConfig
from sasmi.gan.critic import CriticConfig
from sasmi.gan.generator import GeneratorConfig
from sasmi.gan.kinds.autoencoder import AUTOENCODER, AutoencoderRun
from sasmi.gan.kinds.sasgan import SASGAN, SasganRun
from sasmi.gan.loop import train
from sasmi.cli.main import main

from conftest import REPO

PRESET = str(REPO / "scenes" / "muscle_paper.toml")  # the render_set fixture's preset
CPU = torch.device("cpu")


@pytest.fixture(scope="module")
def generator_runs(tmp_path_factory, real_chips, render_set):
    root = tmp_path_factory.mktemp("generate")
    ae = AutoencoderRun(steps=2, size=32, batch=4, autoencoder=AutoencoderConfig((8, 8, 8, 16)),
                        log_every=1, sample_every=10, checkpoint_every=10)
    phi = train(AUTOENCODER, ae, root / "ae", {"real": real_chips / "targets"}, CPU).out
    runs = []
    for seed in (0, 1):
        gan_cfg = SasganRun(steps=2, size=32, batch=2, n_critic=1, seed=seed, generator=GeneratorConfig(4, 1),
                            critic=CriticConfig(4), log_every=1, sample_every=10, checkpoint_every=10)
        inputs = {"real": real_chips / "targets", "renders": render_set, "phi": phi}
        runs.append(train(SASGAN, gan_cfg, root / f"gan{seed}", inputs, CPU).out)
    return runs


def test_generate_keeps_masks_and_labels(tmp_path, generator_runs, render_set, capsys):
    out = tmp_path / "gen"
    args = ["generate", PRESET, "--generator", str(generator_runs[0]), "--out", str(out), "--count", "4",
            "--size", "32", "--spp", "4", "--batch", "3"]
    assert main(args) == 0
    labels = [json.loads(line) for line in (out / "labels.jsonl").read_text().splitlines()]
    plain = [json.loads(line) for line in (render_set / "labels.jsonl").read_text().splitlines()][:4]
    assert labels == plain  # same scenes, same labels
    changed = 0
    for i in range(4):
        name = f"{i:06d}.png"
        assert np.array_equal(np.asarray(Image.open(out / "masks" / name)), np.asarray(Image.open(render_set / "masks" / name)))
        translated = np.asarray(Image.open(out / "images" / name), dtype=int)
        rendered = np.asarray(Image.open(render_set / "images" / name), dtype=int)
        assert translated.shape == rendered.shape
        changed += np.abs(translated - rendered).mean() > 2
    assert changed == 4  # every image went through the generator
    run = json.loads((out / "run.json").read_text())
    assert run["generator"] == str(generator_runs[0].resolve()) and len(run["generator_sha256"]) == 64

    # a different generator may not resume into the same set
    args[args.index("--generator") + 1] = str(generator_runs[1])
    assert main(args) == 2
    assert "other settings" in capsys.readouterr().err


def test_generate_bad_generator_is_one_line(tmp_path, capsys):
    assert main(["generate", PRESET, "--generator", str(tmp_path / "nope"), "--out", str(tmp_path / "o"),
                 "--count", "1", "--size", "32"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "nope" in err
    assert not (tmp_path / "o").exists()


def test_translating_a_tiff16_set_points_its_labels_at_the_pngs(tmp_path, generator_runs):
    renders = tmp_path / "tiff"
    assert main(["render", PRESET, "--out", str(renders), "--count", "2", "--size", "32", "--spp", "2",
                 "--format", "tiff16"]) == 0
    out = tmp_path / "translated"
    assert main(["translate", "--generator", str(generator_runs[0]), "--in", str(renders), "--out", str(out)]) == 0
    for line in (out / "labels.jsonl").read_text().splitlines():
        assert (out / json.loads(line)["image"]).is_file()


def test_generate_defaults_to_the_generators_size_and_takes_a_checkpoint_path(tmp_path, generator_runs):
    out = tmp_path / "gen"
    checkpoint = generator_runs[0] / "checkpoints" / "last.pt"
    assert main(["generate", PRESET, "--generator", str(generator_runs[0]), "--checkpoint", str(checkpoint),
                 "--out", str(out), "--count", "1", "--spp", "2"]) == 0
    assert json.loads((out / "run.json").read_text())["size"] == 32  # the generator was trained at 32 px


def test_generate_on_floors_makes_what_fit_translates(tmp_path, generator_runs, render_set):
    """`sasmi generate --floors` lays scene i on the floor `sasmi fit --floors` gives chip i, then translates."""
    from sasmi.realism.floors import onto_real_floors
    from sasmi.gan.generator import load_generator
    from sasmi.gan.translate import translate
    from sasmi.images import read_gray, write_gray

    rng = np.random.default_rng(0)
    floors, targets = tmp_path / "floors", tmp_path / "targets"
    for i in range(4):
        write_gray(floors / f"f{i}.png", rng.gamma(4.0, 0.4 / 4.0, (32, 32)) * np.linspace(0.6, 1.4, 32)[None])
        target = rng.gamma(4.0, 0.3 / 4.0, (32, 32))
        target[14:18, 12:15], target[14:18, 15:24] = 0.8, 0.02
        write_gray(targets / f"t{i}.png", target)
    out = tmp_path / "gen"
    assert main(["generate", PRESET, "--generator", str(generator_runs[0]), "--out", str(out), "--count", "4",
                 "--size", "32", "--spp", "4", "--floors", str(floors), "--real", str(targets)]) == 0

    on_floors = tmp_path / "on_floors"
    onto_real_floors(render_set, floors, targets, on_floors, 32, seed=0)
    laid = np.stack([read_gray(on_floors / "images" / f"{i:06d}.png") for i in range(4)])
    expected = translate(load_generator(generator_runs[0], CPU), laid)
    generated = np.stack([read_gray(out / "images" / f"{i:06d}.png") for i in range(4)])
    # fit lays the 8-bit render and translates the 8-bit composite, generate the floats: rounding apart
    difference = np.abs(generated - expected)
    assert difference.mean() < 1 / 255 and np.percentile(difference, 99) < 4 / 255
    plain = np.stack([read_gray(render_set / "images" / f"{i:06d}.png") for i in range(4)])
    off_floor = np.abs(generated - translate(load_generator(generator_runs[0], CPU), plain))
    assert off_floor.mean() > 5 / 255  # the floors are not the renders'

    # labels: the render's rocks are not on the real floor, so neither set lists them; both name chip i's floor
    from sasmi.labels import read_labels
    rendered = read_labels(render_set)[:4]
    assert any(label.clutter for label in rendered)  # else this test could not see clutter carried over
    for made in (read_labels(out), read_labels(on_floors)[:4]):
        assert not any(label.clutter for label in made)
        assert [label.extra["floor"] for label in made] == [label.extra["floor"] for label in read_labels(on_floors)[:4]]
        assert all(label.targets == r.targets for label, r in zip(made, rendered))  # the geometry holds
    assert {Path(label.extra["floor"]["seabed"]).parent for label in read_labels(out)} == {floors}


def test_generate_floors_without_real_is_one_line(tmp_path, capsys):
    assert main(["generate", PRESET, "--generator", str(tmp_path / "g"), "--out", str(tmp_path / "o"),
                 "--floors", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--floors and --real" in err and not (tmp_path / "o").exists()


def test_generate_without_a_generator_uses_the_shipped_one_on_seabed_floors(tmp_path, capsys):
    from sasmi import weights

    out = tmp_path / "gen"
    assert main(["generate", str(REPO / "scenes" / "cylinder_chip.toml"), "--out", str(out), "--count", "2",
                 "--spp", "2"]) == 0
    assert "by the shipped generator" in capsys.readouterr().out
    run = json.loads((out / "run.json").read_text())
    assert run["generator"] == str(weights.shipped("sasgan")) and len(run["seabeds_sha256"]) == 64
    labels = [json.loads(line) for line in (out / "labels.jsonl").read_text().splitlines()]
    assert [label["floor"]["seabed_stream"] for label in labels] == [[0, 0], [0, 1]]
    assert labels[0]["floor"]["seabeds"] == str(weights.shipped("seabeds"))
    with Image.open(out / "images" / "000000.png") as image:
        assert image.size == (128, 128)  # the shipped generator's size


@pytest.mark.parametrize("name", ["sasgan", "seabeds"])
def test_generate_without_the_shipped_files_is_one_line_and_writes_nothing(tmp_path, monkeypatch, capsys, name):
    from sasmi import weights

    there = tmp_path / "weights"
    there.mkdir()
    for other, file in weights.FILES.items():
        if other != name:
            (there / file).symlink_to(weights.HERE / file)
    monkeypatch.setattr(weights, "HERE", there)
    out = tmp_path / "gen"
    assert main(["generate", PRESET, "--out", str(out), "--count", "1", "--spp", "2"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{weights.FILES[name]}: the shipped {name} weights are missing" in err
    assert not out.exists()


def test_generate_with_a_seabeds_file_and_bad_ones(tmp_path, generator_runs, capsys):
    from sasmi.realism.seabeds import fit_seabeds, save_seabeds

    rng = np.random.default_rng(0)
    floors = tmp_path / "floors"
    floors.mkdir()
    for i in range(3):
        Image.fromarray((rng.uniform(0.1, 0.5, (32, 32)) * 255).astype(np.uint8)).save(floors / f"{i}.png")
    seabeds = save_seabeds(fit_seabeds(floors), tmp_path / "seabeds.pt")
    out = tmp_path / "gen"
    base = ["generate", PRESET, "--generator", str(generator_runs[0]), "--count", "2", "--size", "32", "--spp", "2"]
    assert main([*base, "--seabeds", str(seabeds), "--out", str(out)]) == 0
    labels = [json.loads(line) for line in (out / "labels.jsonl").read_text().splitlines()]
    assert labels[1]["floor"] == {"seabeds": str(seabeds), "seabed_stream": [0, 1]}
    capsys.readouterr()
    for extra, message in ((["--seabeds", str(tmp_path / "none.pt")], "none.pt: no such seabeds file"),
                           (["--seabeds", str(seabeds), "--floors", str(floors), "--real", str(floors)],
                            "--floors and --seabeds")):
        assert main([*base, *extra, "--out", str(tmp_path / "bad")]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and message in err
        assert not (tmp_path / "bad").exists()


def test_generate_in_two_processes_writes_what_one_process_writes(tmp_path, capsys):
    args = ["generate", str(REPO / "scenes" / "cylinder_chip.toml"), "--count", "5", "--size", "32", "--spp", "2"]
    assert main([*args, "--out", str(tmp_path / "one")]) == 0
    assert main([*args, "--out", str(tmp_path / "two"), "--workers", "2"]) == 0
    assert "wrote 5 translated chips" in capsys.readouterr().out
    files = sorted(p.relative_to(tmp_path / "one") for p in (tmp_path / "one").rglob("*") if p.is_file())
    assert len(files) == 2 + 5 * 5  # run.json, labels.jsonl; per chip its image, three masks and its label
    for name in files:
        assert (tmp_path / "two" / name).read_bytes() == (tmp_path / "one" / name).read_bytes(), name
    assert not (tmp_path / "two" / "claims").exists()
