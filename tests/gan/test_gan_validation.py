"""Bad training flags, bad checkpoints and resume mistakes: one line naming the culprit, exit 2.

Also the resume contract: data identity, honest step reports, --checkpoint-every, and a
best.pt that does not depend on where a run was interrupted.
"""
import os
import pickle
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

from sasmi.gan.autoencoder import AutoencoderConfig
from sasmi.gan.critic import CriticConfig
from sasmi.errors import SasmiError
from sasmi.gan.generator import GeneratorConfig
from sasmi.gan.kinds.autoencoder import AUTOENCODER, AutoencoderRun
from sasmi.gan.kinds.sasgan import SASGAN, SasganRun
from sasmi.gan.loop import resolve_config, train
from sasmi.cli.main import main
from sasmi.images import write_gray

CPU = torch.device("cpu")
TINY = ["--size", "32", "--batch", "2", "--device", "cpu"]
AE_CFG = AutoencoderRun(steps=2, size=32, batch=2, autoencoder=AutoencoderConfig((8, 8, 8, 16)),
                        sample_every=100, checkpoint_every=100)


def _folder(root: Path, n: int = 4, seed: int = 0) -> Path:
    rng = np.random.default_rng(seed)
    for i in range(n):
        write_gray(root / f"{i}.png", rng.random((32, 32)))
    return root


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """Image folders, a 2-step autoencoder run and a 2-step SAS GAN run at 32 px."""
    root = tmp_path_factory.mktemp("validation")
    images = _folder(root / "images")
    ae = train(AUTOENCODER, AE_CFG, root / "ae", {"real": images}, CPU).out
    cfg = SasganRun(steps=2, size=32, batch=2, n_critic=1, generator=GeneratorConfig(4, 1), critic=CriticConfig(4),
                    sample_every=100, checkpoint_every=100)
    gan = train(SASGAN, cfg, root / "gan", {"real": images, "renders": images, "phi": ae}, CPU).out
    return {"images": images, "ae": ae, "gan": gan}


def _one_line_error(capsys, argv, *names):
    assert main(argv) == 2
    captured = capsys.readouterr()
    err = captured.err
    assert err.count("\n") == 1 and err.startswith(f"sasmi {argv[0]}: error: "), err
    assert "Traceback" not in err + captured.out
    for name in names:
        assert name in err, (name, err)
    return err


@pytest.mark.parametrize("flags, named", [
    (["--lr", "nan"], "--lr nan"), (["--lr", "-1"], "--lr -1"), (["--lr", "inf"], "--lr inf"),
    (["--betas", "2", "2"], "--betas 2"), (["--betas", "0.5", "nan"], "--betas nan"),
    (["--n-critic", "0"], "--n-critic 0"), (["--n-critic", "-3"], "--n-critic -3"),
    (["--batch", "0"], "--batch 0"), (["--steps", "0"], "--steps 0"), (["--steps", "100000000000"], "--steps 100000000000"),
    (["--size", "40"], "--size 40"), (["--size", "4096"], "--size 4096"),
    (["--checkpoint-every", "0"], "--checkpoint-every 0"), (["--gp-weight", "inf"], "--gp-weight inf"),
    (["--phi-weight", "-1"], "--phi-weight -1"), (["--phi-margin", "nan"], "--phi-margin nan"),
    (["--critic-lr", "0"], "--critic-lr 0"), (["--r1-gamma", "-1"], "--r1-gamma -1"), (["--ema", "1.5"], "--ema 1.5"),
    (["--mask-weight", "nan"], "--mask-weight nan"), (["--mask-keep", "-0.5"], "--mask-keep -0.5"),
    (["--seed", "-1"], "--seed -1"), (["--threads", "0"], "--threads 0"), (["--device", "tpu"], "--device 'tpu'"),
])
def test_bad_training_flags_are_one_line_naming_the_flag(tmp_path, capsys, runs, flags, named):
    out = tmp_path / "run"
    argv = ["train", "sasgan", "--real", str(runs["images"]), "--renders", str(runs["images"]),
            "--phi", str(runs["ae"]), "--out", str(out), *TINY, *flags]
    flag, _, value = named.partition(" ")
    err = _one_line_error(capsys, argv, flag, value)
    assert any(word in err for word in ("must be", "expected", "allowed"))  # says what is allowed
    assert not out.exists()


def _evil_checkpoint(path: Path) -> None:
    class Evil:
        def __reduce__(self):
            return os.system, (f"touch {path.parent / 'pwned'}",)

    torch.save({"step": 1, "state": Evil()}, path)


CORRUPTIONS = {
    "empty": lambda p: p.write_bytes(b""),
    "truncated": lambda p: p.write_bytes(p.read_bytes()[:200]),
    "random bytes": lambda p: p.write_bytes(np.random.default_rng(0).bytes(4096)),
    "a plain tensor": lambda p: torch.save(torch.zeros(3), p),
    "a pickle carrying code": _evil_checkpoint,
}


@pytest.mark.parametrize("corruption", sorted(CORRUPTIONS))
def test_broken_checkpoints_are_one_line_naming_the_file(tmp_path, capsys, runs, corruption):
    run = tmp_path / "gan"
    (run / "checkpoints").mkdir(parents=True)
    last = run / "checkpoints" / "last.pt"
    last.write_bytes((runs["gan"] / "checkpoints" / "last.pt").read_bytes())
    CORRUPTIONS[corruption](last)
    out = tmp_path / "out"
    err = _one_line_error(capsys, ["translate", "--generator", str(run), "--in", str(runs["images"]),
                                   "--out", str(out)], str(last))
    assert ("could run code" in err) == (corruption == "a pickle carrying code"), err
    assert not out.exists() and not (run / "pwned").exists()
    # the same file met as --phi and on --resume
    _one_line_error(capsys, ["train", "sasgan", "--real", str(runs["images"]), "--renders", str(runs["images"]),
                             "--phi", str(run), "--out", str(tmp_path / "g"), *TINY], str(last))
    _one_line_error(capsys, ["train", "autoencoder", "--real", str(runs["images"]), "--out", str(run), "--resume",
                             *TINY], str(last))
    assert not (tmp_path / "g").exists() and not (run / "pwned").exists()


def test_checkpoints_of_another_kind_or_architecture(tmp_path, capsys, runs):
    out = str(tmp_path / "out")
    _one_line_error(capsys, ["translate", "--generator", str(runs["ae"]), "--in", str(runs["images"]), "--out", out],
                    "is a 'autoencoder' run, expected a 'sasgan' run")
    run = tmp_path / "wider"
    (run / "checkpoints").mkdir(parents=True)
    ckpt = torch.load(runs["gan"] / "checkpoints" / "last.pt", weights_only=True)
    ckpt["config"]["generator"]["width"] = 8  # the weights are of a width-4 generator
    torch.save(ckpt, run / "checkpoints" / "last.pt")
    _one_line_error(capsys, ["translate", "--generator", str(run), "--in", str(runs["images"]), "--out", out],
                    str(run / "checkpoints" / "last.pt"), "do not fit")
    assert not Path(out).exists()


def test_resume_onto_other_data_is_refused(tmp_path, capsys, runs):
    out = tmp_path / "ae"
    common = ["--out", str(out), *TINY]
    assert main(["train", "autoencoder", "--real", str(runs["images"]), "--steps", "2", *common]) == 0
    before = (out / "checkpoints" / "last.pt").read_bytes()
    other = _folder(tmp_path / "other", n=5, seed=1)
    _one_line_error(capsys, ["train", "autoencoder", "--real", str(other), "--steps", "4", "--resume", *common],
                    f"--real {other}", "not the data this run was trained on")
    assert (out / "checkpoints" / "last.pt").read_bytes() == before


def test_resume_reports_steps_honestly(tmp_path, capsys, runs):
    common = ["--real", str(runs["images"]), "--out", str(tmp_path / "ae"), *TINY]
    assert main(["train", "autoencoder", "--steps", "4", *common]) == 0
    assert "trained steps 1-4" in capsys.readouterr().out
    assert main(["train", "autoencoder", "--steps", "2", "--resume", *common]) == 0
    assert "already at step 4 (--steps 2); nothing trained" in capsys.readouterr().out
    assert main(["train", "autoencoder", "--steps", "6", "--resume", *common]) == 0
    assert "trained steps 5-6" in capsys.readouterr().out
    assert torch.load(tmp_path / "ae" / "checkpoints" / "last.pt", weights_only=True)["step"] == 6


def test_checkpoint_every_sets_the_interval(tmp_path, runs, monkeypatch):
    import sasmi.gan.kinds.autoencoder as kind
    from sasmi.gan.losses import reconstruction_loss

    calls = []

    def stop_at_5(reconstruction, target):  # a non-finite loss stops the run with last.pt untouched
        calls.append(1)
        return reconstruction_loss(reconstruction, target) * (float("nan") if len(calls) == 5 else 1.0)

    monkeypatch.setattr(kind, "reconstruction_loss", stop_at_5)
    with pytest.raises(Exception, match="last good state \\(step 4\\)"):
        train(AUTOENCODER, replace(AE_CFG, steps=9, checkpoint_every=2), tmp_path / "ae", {"real": runs["images"]},
              CPU)
    assert torch.load(tmp_path / "ae" / "checkpoints" / "last.pt", weights_only=True)["step"] == 4


def test_best_checkpoint_does_not_depend_on_interruptions(tmp_path, runs):
    cfg = replace(AE_CFG, steps=20, checkpoint_every=5)
    inputs = {"real": runs["images"]}
    train(AUTOENCODER, cfg, tmp_path / "straight", inputs, CPU)
    for steps in (7, 13, 20):  # stopped between checkpoints and resumed, twice
        resume = steps != 7
        run_cfg = resolve_config(AUTOENCODER, tmp_path / "split", {"steps": steps}, True) if resume \
            else replace(cfg, steps=steps)
        train(AUTOENCODER, run_cfg, tmp_path / "split", inputs, CPU, resume)
    a, b = (torch.load(tmp_path / r / "checkpoints" / "best.pt", weights_only=True) for r in ("straight", "split"))
    assert a["step"] == b["step"] and a["step"] % 5 == 0 and a["best"] == b["best"]
    assert all(torch.equal(a["state"]["autoencoder"][k], b["state"]["autoencoder"][k])
               for k in a["state"]["autoencoder"])


def test_config_travels_inside_the_checkpoint(runs):
    ckpt = torch.load(runs["gan"] / "checkpoints" / "last.pt", weights_only=True)
    assert ckpt["kind"] == "sasgan" and ckpt["config"]["generator"] == {"width": 4, "blocks": 1, "residual": False,
                                                                     "correction_scale": 1, "tone_curve": False,
                                                                     "tone_style": False, "donor_levels": False,
                                                                     "donor_levels_after": False, "donor_shadow": 0.0}
    assert set(ckpt["inputs"]) == {"real", "renders", "phi"}
    assert pickle.loads(pickle.dumps(ckpt["config"])) == ckpt["config"]  # plain types only


def test_checkpoints_from_before_the_config_moved_inside_still_load(tmp_path, runs):
    from sasmi.gan.generator import load_generator

    run = tmp_path / "old"
    (run / "checkpoints").mkdir(parents=True)
    ckpt = torch.load(runs["gan"] / "checkpoints" / "last.pt", weights_only=True)
    old = {k: ckpt[k] for k in ("step", "torch_rng", "state")}  # no kind, no config: the run's config.json has them
    old["state"] = {k: v for k, v in old["state"].items() if k != "generator_ema"}
    torch.save(old, run / "checkpoints" / "last.pt")
    (run / "config.json").write_text((runs["gan"] / "config.json").read_text())
    generator = load_generator(run)
    assert generator.image_size == 32
    assert all(torch.equal(p, ckpt["state"]["generator"][k]) for k, p in generator.state_dict().items())


def test_correction_scale_needs_the_residual_generator_and_must_divide_the_size():
    def run(**generator) -> SasganRun:
        return SasganRun(size=32, generator=GeneratorConfig(**generator)).validate()

    assert run(residual=True, correction_scale=4).generator.correction_scale == 4
    for bad in ({"correction_scale": 4}, {"residual": True, "correction_scale": 3},
                {"residual": True, "correction_scale": 0}):
        with pytest.raises(SasmiError, match="correction_scale"):
            run(**bad)
