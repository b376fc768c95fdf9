"""Training runs at 32 px on the CPU: checkpoints, samples, exact resume, NaN stop, loading, translate."""
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

import sasmi.gan.kinds.autoencoder
from sasmi.gan.autoencoder import Autoencoder, AutoencoderConfig, load_encoder
from sasmi.gan.critic import CriticConfig
from sasmi.gan.data import ImageSet
from sasmi.gan.dcgan import DCGANConfig, load_dcgan, sample
from sasmi.gan.generator import GeneratorConfig, load_generator
from sasmi.gan.kinds.autoencoder import AUTOENCODER, AutoencoderRun
from sasmi.gan.kinds.dcgan import DCGAN, DcganRun
from sasmi.gan.kinds.sasgan import SASGAN, SasganRun
from sasmi.gan.loop import resolve_config, train
from sasmi.gan.losses import reconstruction_loss
from sasmi.gan.translate import translate, translate_folder
from sasmi.errors import SasmiError
from sasmi.labels import ChipLabel, TargetLabel
from sasmi.images import read_gray, write_gray
from sasmi.masks import write_class_mask

CPU = torch.device("cpu")
TINY_AE = AutoencoderRun(steps=4, size=32, batch=4, autoencoder=AutoencoderConfig((8, 8, 8, 16)),
                         log_every=1, sample_every=10, checkpoint_every=10)
TINY_SASGAN = SasganRun(steps=20, size=32, batch=2, n_critic=2, generator=GeneratorConfig(4, 1),
                        critic=CriticConfig(4), log_every=1, sample_every=10, checkpoint_every=10, best_from=0)
TINY_DCGAN = DcganRun(steps=20, size=32, batch=2, n_critic=2, dcgan=DCGANConfig(8, 4), critic=CriticConfig(4),
                      final_samples=3, log_every=1, sample_every=10, checkpoint_every=10, best_from=0)


def train_ae(cfg, out, real, resume=False):
    return train(AUTOENCODER, cfg, out, {"real": real}, CPU, resume).out


def train_sasgan(cfg, out, real, renders, phi, resume=False):
    return train(SASGAN, cfg, out, {"real": real, "renders": renders, "phi": phi}, CPU, resume).out


def train_dcgan(cfg, out, real, resume=False):
    return train(DCGAN, cfg, out, {"real": real}, CPU, resume).out


def toy_gan_inputs(root: Path, size: int, phi_steps: int) -> dict:
    """'Real' speckle chips, a render set (disc + shadow) and a φ autoencoder trained `phi_steps` on the real ones."""
    rng = np.random.default_rng(0)
    for i in range(8):
        write_gray(root / "real" / f"{i}.png", np.clip(rng.gamma(2.0, 0.25, (size, size)), 0, 1))
    renders = make_render_set(root / "renders", n=8, size=size)
    ae_cfg = AutoencoderRun(steps=phi_steps, size=size, batch=4, autoencoder=AutoencoderConfig((8, 8, 8, 16)),
                            sample_every=100, checkpoint_every=100)
    phi = train(AUTOENCODER, ae_cfg, root / "ae", {"real": root / "real"}, CPU).out
    return {"real": root / "real", "renders": renders, "phi": phi}


def sasgan_straight_and_resumed(cfg: SasganRun, root: Path, data: dict) -> tuple[dict, dict]:
    """The last checkpoint's state of a SAS GAN trained `cfg.steps` straight, and of one stopped at
    half and resumed (cfg.checkpoint_every must divide the half)."""
    straight = train(SASGAN, cfg, root / "straight", data, CPU).out
    train(SASGAN, replace(cfg, steps=cfg.steps // 2), root / "resumed", data, CPU)
    resumed = train(SASGAN, cfg, root / "resumed", data, CPU, resume=True).out
    return tuple(torch.load(out / "checkpoints" / "last.pt", weights_only=True)["state"] for out in (straight, resumed))


def make_render_set(folder: Path, n: int = 6, size: int = 48, seed: int = 0) -> Path:
    """A render set as `sasmi render` writes it: seafloor, a bright target, its shadow to the right."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[:size, :size]
    labels = []
    for i in range(n):
        cy, cx, r = rng.uniform(0.3, 0.7) * size, rng.uniform(0.3, 0.5) * size, 0.1 * size
        image = np.clip(0.35 + 0.05 * rng.standard_normal((size, size)), 0, 1)
        target = (yy - cy) ** 2 + (xx - cx) ** 2 < r ** 2
        shadow = (abs(yy - cy) < r) & (xx > cx + r) & (xx < cx + 4 * r)
        image[shadow], image[target] = 0.05, 0.9
        mask = np.zeros((size, size), np.uint8)
        mask[target], mask[shadow] = 1, 2
        write_gray(folder / "images" / f"{i:06d}.png", image)
        write_class_mask(folder / "masks" / f"{i:06d}.png", mask)
        target_label = TargetLabel(params={"shape": "cylinder"}, pixel_centre=(cx, cy),
                                   bbox=(cx - r, cy - r, cx + r, cy + r), shadow_bbox=(cx + r, cy - r, cx + 4 * r, cy + r))
        labels.append(ChipLabel(index=i, size=size, scene={}, targets=(target_label,), image=f"images/{i:06d}.png",
                                mask=f"masks/{i:06d}.png").dumps())
    (folder / "labels.jsonl").write_text("\n".join(labels) + "\n")
    (folder / "run.json").write_text("{}\n")
    return folder


@pytest.fixture(scope="module")
def chips(real_chips):
    return real_chips  # tests/conftest.py: skips when the shared chips are absent


@pytest.fixture(scope="module")
def renders(tmp_path_factory):
    return make_render_set(tmp_path_factory.mktemp("renders"))


@pytest.fixture(scope="module")
def ae_run(tmp_path_factory, chips):
    return train_ae(TINY_AE, tmp_path_factory.mktemp("runs") / "ae", chips)


def _tensors(state, prefix=""):
    """Flatten a checkpoint into {path: tensor or number}."""
    if isinstance(state, dict):
        return {k: v for key, sub in state.items() for k, v in _tensors(sub, f"{prefix}/{key}").items()}
    if isinstance(state, (list, tuple)):
        return {k: v for i, sub in enumerate(state) for k, v in _tensors(sub, f"{prefix}/{i}").items()}
    return {prefix: state}


def test_autoencoder_overfits_a_batch_of_8(chips):
    torch.manual_seed(0)
    images = ImageSet(chips / "targets", 32)
    x = images.center(list(range(8)))  # (8, 1, 32, 32) in [-1, 1]
    model = Autoencoder(AutoencoderConfig())
    opt = torch.optim.Adam(model.parameters(), lr=1e-3)
    losses = []
    for _ in range(80):
        loss = reconstruction_loss(model(x), x)
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(loss.item())
    assert losses[-1] < losses[0] / 10, (losses[0], losses[-1])


def test_sasgan_run_writes_checkpoints_samples_and_log(tmp_path, chips, renders, ae_run):
    out = train_sasgan(TINY_SASGAN, tmp_path / "sasgan", chips, renders, ae_run)
    record = json.loads((out / "config.json").read_text())
    assert record["config"]["phi_margin"] == TINY_SASGAN.phi_margin
    assert record["provenance"]["torch"] == torch.__version__ and len(record["provenance"]["git_commit"] or "") == 40
    assert record["provenance"]["sasmi"] and record["provenance"]["command"]
    assert sorted(p.name for p in (out / "samples").iterdir()) == ["step_000010.png", "step_000020.png"]
    assert read_gray(out / "samples" / "step_000020.png").shape == (2 * 34 + 2, 6 * 34 + 2)  # renders | outputs
    assert list((out / "tb").glob("events.out.tfevents.*"))
    for which in ("last", "best"):
        ckpt = torch.load(out / "checkpoints" / f"{which}.pt", weights_only=True)
        assert set(ckpt["state"]) == {"generator", "generator_ema", "critic", "opt_g", "opt_c", "real", "renders",
                                      "noise", "view_noise"}
    assert torch.load(out / "checkpoints" / "last.pt", weights_only=True)["step"] == 20
    assert not list(out.rglob("*.tmp*"))  # atomic writes left nothing behind

    generator = load_generator(out)
    assert generator.image_size == 32 and not generator.training
    y = generator(torch.rand(3, 1, 32, 32) * 2 - 1)
    assert y.shape == (3, 1, 32, 32) and y.abs().max() <= 1


@pytest.mark.parametrize("kind", ["autoencoder", "sasgan", "dcgan"])
def test_ten_steps_resume_ten_steps_equals_twenty(tmp_path, chips, renders, ae_run, kind):
    kinds = {"autoencoder": AUTOENCODER, "sasgan": SASGAN, "dcgan": DCGAN}
    inputs = {"real": chips} | ({"renders": renders, "phi": ae_run} if kind == "sasgan" else {})

    def run(cfg, out, resume=False):
        return train(kinds[kind], cfg, out, inputs, CPU, resume)

    cfg = replace({"autoencoder": TINY_AE, "sasgan": TINY_SASGAN, "dcgan": TINY_DCGAN}[kind], steps=20,
                  checkpoint_every=100, sample_every=100)
    run(cfg, tmp_path / "straight")
    run(replace(cfg, steps=10), tmp_path / "split")
    resumed = resolve_config(kinds[kind], tmp_path / "split", {"steps": 20}, resume=True)
    run(resumed, tmp_path / "split", resume=True)

    a = _tensors(torch.load(tmp_path / "straight" / "checkpoints" / "last.pt", weights_only=True))
    b = _tensors(torch.load(tmp_path / "split" / "checkpoints" / "last.pt", weights_only=True))
    assert a.keys() == b.keys() and a["/step"] == b["/step"] == 20
    same = {k: torch.equal(a[k], b[k]) if torch.is_tensor(a[k]) else a[k] == b[k] for k in a}
    assert not [k for k, ok in same.items() if not ok]


def test_non_finite_loss_stops_and_keeps_the_last_good_checkpoint(tmp_path, chips, monkeypatch):
    calls = []

    def poisoned(reconstruction, target):
        calls.append(1)
        loss = reconstruction_loss(reconstruction, target)
        return loss * float("nan") if len(calls) == 7 else loss

    monkeypatch.setattr(sasmi.gan.kinds.autoencoder, "reconstruction_loss", poisoned)
    cfg = replace(TINY_AE, steps=20, checkpoint_every=5)
    with pytest.raises(SasmiError, match=r"step 7: non-finite loss/reconstruction = nan.*last good state \(step 5\)"):
        train_ae(cfg, tmp_path / "ae", chips)
    ckpt = torch.load(tmp_path / "ae" / "checkpoints" / "last.pt", weights_only=True)
    assert ckpt["step"] == 5
    assert all(torch.isfinite(v).all() for v in ckpt["state"]["autoencoder"].values())


def test_resume_refuses_changed_settings_and_fresh_runs_refuse_old_folders(tmp_path, chips):
    out = train_ae(TINY_AE, tmp_path / "ae", chips)
    with pytest.raises(SasmiError, match="size=64"):
        resolve_config(AUTOENCODER, out, {"size": 64, "steps": 8}, resume=True)
    with pytest.raises(SasmiError, match="already holds a run"):
        resolve_config(AUTOENCODER, out, {}, resume=False)
    with pytest.raises(SasmiError, match="is a 'autoencoder' run"):
        resolve_config(SASGAN, out, {}, resume=True)
    with pytest.raises(SasmiError, match="nothing to resume"):
        resolve_config(AUTOENCODER, tmp_path / "new", {}, resume=True)


def test_load_encoder(ae_run):
    encoder = load_encoder(ae_run)
    assert encoder.image_size == 32 and not encoder.training
    assert encoder(torch.zeros(2, 1, 32, 32)).shape == (2, 1024)


def test_dcgan_run_writes_final_samples_and_loads(tmp_path, chips):
    out = train_dcgan(replace(TINY_DCGAN, steps=2), tmp_path / "dcgan", chips)
    assert len(list((out / "final_samples").glob("*.png"))) == 3
    generator = load_dcgan(out)
    assert generator.image_size == 32
    images = sample(generator, 5, seed=3)
    assert images.shape == (5, 32, 32) and 0 <= images.min() and images.max() <= 1


@pytest.fixture(scope="module")
def generator(tmp_path_factory, chips, renders, ae_run):
    out = train_sasgan(replace(TINY_SASGAN, steps=2), tmp_path_factory.mktemp("runs") / "g", chips, renders, ae_run)
    return load_generator(out)


def test_translate_resizes_in_and_out(generator):
    images = np.random.default_rng(0).random((5, 48, 40))
    out = translate(generator, images, batch=2)
    assert out.shape == (5, 48, 40) and out.dtype == np.float32
    assert 0 <= out.min() and out.max() <= 1
    np.testing.assert_allclose(translate(generator, images[:1]), out[:1], atol=1e-5)  # batching does not matter


def test_translate_folder_carries_render_set_labels(tmp_path, generator, renders):
    n = translate_folder(generator, renders, tmp_path / "out", batch=4)
    assert n == 6
    assert sorted(p.name for p in (tmp_path / "out" / "images").iterdir()) == [f"{i:06d}.png" for i in range(6)]
    assert read_gray(tmp_path / "out" / "images" / "000000.png").shape == (48, 48)
    assert (tmp_path / "out" / "labels.jsonl").read_text() == (renders / "labels.jsonl").read_text()
    assert sorted(p.name for p in (tmp_path / "out" / "masks").iterdir()) == [f"{i:06d}.png" for i in range(6)]
    with pytest.raises(SasmiError, match="outside the input"):
        translate_folder(generator, renders, renders / "images" / "out")


def test_a_rerun_removes_what_a_killed_translation_was_writing(tmp_path, generator, renders):
    """SIGKILL inside a PNG write leaves its hidden temporary (sasmi.images.atomic_path); the rerun clears it."""
    out = tmp_path / "out"
    translate_folder(generator, renders, out, batch=4)
    (out / "images" / "000003.png").unlink()
    leftover = out / "images" / ".000003.png.k1ll3d.tmp.png"  # as atomic_path names it
    leftover.write_bytes(b"\x89PNG half")
    assert translate_folder(generator, renders, out, batch=4) == 6
    assert sorted(p.name for p in (out / "images").iterdir()) == [f"{i:06d}.png" for i in range(6)]


class _Identity(torch.nn.Module):
    """A stand-in generator that returns its input and records the shapes it was shown."""

    def __init__(self, image_size: int):
        super().__init__()
        self.weight = torch.nn.Parameter(torch.zeros(1))  # translate() asks the parameters for the device
        self.image_size, self.shapes = image_size, []

    def forward(self, x):
        self.shapes.append(tuple(x.shape[-2:]))
        return x


@pytest.mark.parametrize("shape, seen, scaled", [((64, 128), (32, 64), (32, 64)),  # aspect kept, not squashed
                                                  ((48, 40), (40, 32), (38, 32))])  # padded to a multiple of 4
def test_translate_shows_the_generator_what_training_showed_it(shape, seen, scaled):
    from sasmi.preprocess import resize

    images = np.random.default_rng(0).random((2, *shape)).astype(np.float32)
    generator = _Identity(32)
    out = translate(generator, images)
    assert generator.shapes == [seen]  # short side at the training size, as ImageSet scales training images
    x = torch.from_numpy(images)[:, None]
    expected = resize(resize(x, scaled), shape)[:, 0].numpy()  # the padding is cropped off again
    np.testing.assert_allclose(out, expected, atol=1e-6)
    squashed = resize(resize(x, (32, 32)), shape)[:, 0].numpy()
    assert np.abs(out - squashed).mean() > 0.01  # squashing to the training square would differ
