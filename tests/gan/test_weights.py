"""Weights files: a run stripped to what loading needs loads in place of the run; files of another format,
truncated files and missing shipped files fail in one line; the shipped files load as they are."""
from __future__ import annotations

import hashlib

import pytest
import torch

from sasmi.errors import SasmiError
from sasmi.gan.autoencoder import AutoencoderConfig, load_encoder
from sasmi.gan.critic import CriticConfig
from sasmi.gan.generator import GeneratorConfig, load_generator
from sasmi.gan.kinds.autoencoder import AUTOENCODER, AutoencoderRun
from sasmi.gan.kinds.sasgan import SASGAN, SasganRun
from sasmi.gan.loop import train
from sasmi.gan.export_weights import export_weights
from sasmi.gan.run import FORMAT, read_run
from sasmi import weights

CPU = torch.device("cpu")


@pytest.fixture(scope="module")
def runs(tmp_path_factory, real_chips, render_set):
    root = tmp_path_factory.mktemp("weights")
    ae = AutoencoderRun(steps=2, size=32, batch=4, autoencoder=AutoencoderConfig((8, 8, 8, 16)),
                        log_every=1, sample_every=10, checkpoint_every=10)
    phi = train(AUTOENCODER, ae, root / "ae", {"real": real_chips / "targets"}, CPU).out
    gan = SasganRun(steps=2, size=32, batch=2, n_critic=1, ema=0.9, generator=GeneratorConfig(4, 1),
                    critic=CriticConfig(4), log_every=1, sample_every=10, checkpoint_every=10)
    sasgan = train(SASGAN, gan, root / "gan", {"real": real_chips / "targets", "renders": render_set, "phi": phi},
                   CPU).out
    return phi, sasgan


def _same_state(a: torch.nn.Module, b: torch.nn.Module) -> bool:
    sa, sb = a.state_dict(), b.state_dict()
    return sa.keys() == sb.keys() and all(torch.equal(sa[k], sb[k]) for k in sa)


def test_exported_weights_load_in_place_of_their_run(runs, tmp_path):
    phi, sasgan = runs
    phi_file = export_weights(phi, "autoencoder", tmp_path / "phi.pt", "best", {"note": "test"})
    gan_file = export_weights(sasgan, "sasgan", tmp_path / "sasgan.pt")
    assert _same_state(load_encoder(phi_file), load_encoder(phi))
    assert _same_state(load_generator(gan_file), load_generator(sasgan))
    assert load_generator(gan_file).image_size == 32
    saved = torch.load(gan_file, weights_only=True)  # tensors and plain types only
    assert set(saved["state"]) == {"generator_ema"} and saved["format"] == FORMAT and saved["step"] == 2
    assert gan_file.stat().st_size < (sasgan / "checkpoints" / "last.pt").stat().st_size / 2  # no critic, no optimiser
    export_weights(sasgan, "sasgan", tmp_path / "again.pt")
    assert hashlib.sha256(gan_file.read_bytes()).digest() == hashlib.sha256((tmp_path / "again.pt").read_bytes()).digest()


def test_weights_of_another_format_or_kind_or_truncated_fail_in_one_line(runs, tmp_path):
    phi, _ = runs
    path = export_weights(phi, "autoencoder", tmp_path / "phi.pt", "best")
    saved = torch.load(path, weights_only=True)
    torch.save({**saved, "format": FORMAT + 1, "sasmi": "9.9"}, tmp_path / "newer.pt")
    with pytest.raises(SasmiError, match=r"newer.pt: checkpoint format 2; this sasmi .* reads format 1 \(written by 9.9\)"):
        load_encoder(tmp_path / "newer.pt")
    with pytest.raises(SasmiError, match="is a 'autoencoder' run, expected a 'sasgan' run"):
        load_generator(path)
    (tmp_path / "cut.pt").write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    with pytest.raises(SasmiError, match="cut.pt: not a readable checkpoint"):
        load_encoder(tmp_path / "cut.pt")
    with pytest.raises(SasmiError, match="has no generator_ema weights to export"):
        export_weights(_without_ema(runs[1], tmp_path), "sasgan", tmp_path / "y.pt")
    assert not (tmp_path / "y.pt").exists()


def _without_ema(run, tmp_path):
    saved = torch.load(run / "checkpoints" / "last.pt", weights_only=True)
    saved["state"].pop("generator_ema")
    torch.save(saved, tmp_path / "no_ema.pt")
    return tmp_path / "no_ema.pt"


def test_a_checkpoint_without_a_format_key_is_of_format_one(runs, tmp_path):
    saved = torch.load(runs[0] / "checkpoints" / "last.pt", weights_only=True)
    assert saved["format"] == FORMAT
    saved.pop("format")
    torch.save(saved, tmp_path / "old.pt")
    assert read_run(tmp_path / "old.pt", "autoencoder").step == 2


def test_a_missing_shipped_file_names_itself_and_the_flag_to_pass(tmp_path, monkeypatch):
    monkeypatch.setattr(weights, "HERE", tmp_path)
    with pytest.raises(SasmiError, match=r"sasgan.pt: the shipped sasgan weights are missing .* pass --generator RUN"):
        weights.shipped("sasgan")


def test_the_shipped_weights_load():
    from sasmi.realism.seabeds import load_seabeds

    encoder, generator = load_encoder(weights.shipped("phi")), load_generator(weights.shipped("sasgan"))
    assert encoder.image_size == generator.image_size == 128
    assert len(generator.donors) > 0  # the real chips' gray levels travel with it
    assert len(load_seabeds(weights.shipped("seabeds")).mean) > 0
    for name in weights.FILES:
        assert weights.shipped(name).stat().st_size < 5e6  # small enough to ship in the repository


@pytest.mark.slow
def test_the_reference_weights_script_retrains_bit_for_bit(real_chips, tmp_path):
    import subprocess
    import sys

    from conftest import REPO

    digests = []
    for run in ("a", "b"):
        subprocess.run([sys.executable, str(REPO / "benchmarks" / "reference_weights.py"), "--chips", str(real_chips),
                        "--out", str(tmp_path / run), "--tiny"], check=True, capture_output=True)
        digests.append({name: hashlib.sha256((tmp_path / run / "weights" / file).read_bytes()).hexdigest()
                        for name, file in weights.FILES.items()})
    assert digests[0] == digests[1]
    assert load_generator(tmp_path / "a" / "weights" / "sasgan.pt").image_size == 32
