"""Differentiable scenes: the render it differentiates, gradients against central differences,
recovery of a known roughness, the fitted preset and `sasmi fit-scene` end to end."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from sasmi.cli.main import main
from sasmi.errors import SasmiError
from sasmi.realism.fit_scene import (FitConfig, central_difference, fit_scene, parse_params, preset_toml, scale_bounds,
                       scaled_preset)
from sasmi.render.differentiable import PARAMETERS, DifferentiableRenderer, scene_parameters
from sasmi.render.mitsuba import Renderer
from sasmi.scene.preset import Preset, load_preset

REPO = Path(__file__).resolve().parents[2]
SIZE, SPP = 64, 4


def relief_preset(rms_height: float = 0.02, ripple_amplitude: float = 0.01, **post) -> Preset:
    """Rough, rippled sand without rocks or targets: no shadow edges that AD would miss."""
    return Preset.from_dict({
        "sonar": {"max_range": 60.0, "near_range": 30.0, "chip_size": 6.0, "emitters": 8},
        "seafloor": {"albedo": 0.5, "rms_height": rms_height, "correlation_length": 0.3,
                     "ripple_amplitude": ripple_amplitude, "ripple_wavelength": 0.8},
        "post": {"speckle_looks": 4.0, "noise_std": 0.02, **post}})


@pytest.fixture(scope="module")
def renderer() -> DifferentiableRenderer:
    return DifferentiableRenderer(SIZE, SPP)


@pytest.fixture(scope="module")
def encoder() -> torch.nn.Module:
    """A randomly initialised φ encoder of the real architecture: random conv features see texture."""
    from sasmi.gan.autoencoder import AutoencoderConfig, Encoder

    torch.manual_seed(0)
    encoder = Encoder(AutoencoderConfig()).eval().requires_grad_(False)
    encoder.image_size = SIZE
    return encoder


def phi(encoder, images: torch.Tensor) -> torch.Tensor:
    return encoder(images.reshape(-1, 1, SIZE, SIZE) * 2.0 - 1.0)  # (B, 1024)


def test_image_is_the_forward_render(renderer):
    scene = load_preset(REPO / "scenes" / "cylinder_chip.toml").sample(0, 0)
    image = renderer.image(renderer.bind(scene), torch.tensor(scene_parameters(scene)), scene.seed).numpy()
    reference = Renderer(SIZE, SPP).render(scene).image
    assert np.abs(image - reference).max() < 1e-4


def test_fitted_preset_renders_what_was_fitted(renderer):
    """θ scaled in the differentiable render == the scaled preset rendered normally (targets ride along)."""
    preset = load_preset(REPO / "scenes" / "cylinder_chip.toml")
    scales = {"seafloor.roughness": 1.7, "seafloor.albedo": 0.8, "sonar.intensity": 1.3, "sonar.elevation": 1.1}
    scene = preset.sample(0, 0)
    theta = torch.tensor(scene_parameters(scene) * [scales[p] for p in PARAMETERS])
    image = renderer.image(renderer.bind(scene), theta, scene.seed).numpy()
    fitted = Preset.from_dict(scaled_preset(preset, scales)).sample(0, 0)
    assert fitted.sonar.array_altitude == pytest.approx(scene.sonar.array_altitude * 1.1)
    reference = Renderer(SIZE, SPP).render(fitted).image
    assert np.abs(image - reference).mean() < 1e-3 and np.abs(image - reference).max() < 0.05


@pytest.mark.parametrize("name", PARAMETERS)
def test_gradient_matches_central_difference(renderer, encoder, name):
    """d loss / d θ through φ (torch → Dr.Jit and back) against a 3 % central difference at the same sample
    seed, on relief gentle enough not to shadow itself: the chain through the encoder. The tight check,
    averaged over seeds on rough floors and a target, is tests/realism/test_gradients.py."""
    from sasmi.gan.losses import phi_loss

    scene = relief_preset(0.01, 0.005).sample(0, 0)
    bound = renderer.bind(scene, speckle=False)
    theta0 = scene_parameters(scene)
    with torch.no_grad():
        target = phi(encoder, renderer.image(bound, torch.tensor(theta0 * [1.5, 1.2, 0.8, 1.2]), seed=99))

    def loss(theta: torch.Tensor) -> torch.Tensor:
        return phi_loss(target, phi(encoder, renderer.image(bound, theta, seed=7)), 0.0)

    theta = torch.tensor(theta0, dtype=torch.float32, requires_grad=True)
    loss(theta).backward()
    i = PARAMETERS.index(name)
    with torch.no_grad():
        fd = central_difference(lambda x: loss(torch.tensor(x)).item(), theta0, i, 0.03 * theta0[i])
    ratio = theta.grad[i].item() / fd
    print(f"{name}: AD {theta.grad[i].item():.4g}, central difference {fd:.4g}, ratio {ratio:.3f}")
    assert 0.7 < ratio < 1.3, ratio


def test_scenes_add_up(renderer):
    """A loss over two scenes gets both scenes' gradients (one Mitsuba scene per bound scene)."""
    preset = relief_preset(0.01, 0.005)
    bounds = [renderer.bind(preset.sample(0, k)) for k in range(2)]

    def grad(which: list[int]) -> np.ndarray:
        scale = torch.ones(len(PARAMETERS), requires_grad=True)
        sum(renderer.image(bounds[k], torch.tensor(scene_parameters(bounds[k].scene)) * scale, seed=5 + k).mean()
            for k in which).backward()
        return scale.grad.numpy()

    np.testing.assert_allclose(grad([0, 1]), grad([0]) + grad([1]), rtol=1e-3, atol=1e-6)


@pytest.mark.parametrize("start", [0.3, 3.0])
def test_recovers_roughness_from_far_starts(encoder, start):
    """Chips of a known roughness r*, scenes the fit never renders, are the real chips; fits started at 0.3 r*
    and 3 r* end within 15 % of r*."""
    truth = relief_preset(0.02, 0.01)
    cfg = FitConfig(params=("seafloor.roughness",), steps=40, lr=0.2, scenes=8, size=SIZE, spp=SPP)
    renderer = DifferentiableRenderer(SIZE, SPP)
    with torch.no_grad():
        scenes = [truth.sample(cfg.seed + 1, k) for k in range(8)]  # the fit renders scenes of cfg.seed
        images = [renderer.image(renderer.bind(s), torch.tensor(scene_parameters(s)), 10_000 + k)
                  for k, s in enumerate(scenes)]
        target = phi(encoder, torch.stack(images)).numpy()  # (8, D)
    result = fit_scene(relief_preset(0.02 * start, 0.01 * start), encoder, target, cfg, progress=False)
    fitted = scaled_preset(relief_preset(0.02 * start, 0.01 * start), result.scales)["seafloor"]
    print(f"from x{start}: roughness x{fitted['rms_height'] / 0.02:.3f}, {result.seconds_per_step:.2f} s per step")
    assert result.trajectory[-1]["loss"] < 0.8 * result.trajectory[0]["loss"]
    assert fitted["rms_height"] == pytest.approx(0.02, rel=0.15)
    assert fitted["ripple_amplitude"] == pytest.approx(0.01, rel=0.15)


def test_scaled_preset_keeps_distributions_and_limits(tmp_path):
    mesh = tmp_path / "box.obj"
    mesh.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 2 4\nf 1 3 4\nf 2 3 4\n")
    preset = Preset.from_dict({
        "sonar": {"near_range": {"uniform": [30.0, 50.0]}, "max_range": 60.0},
        "seafloor": {"albedo": {"uniform": [0.4, 0.6]}, "rms_height": {"normal": [0.01, 0.002]},
                     "ripple_amplitude": {"choice": [0.0, 0.01]}},
        "targets": [{"shape": "mesh", "mesh": "box.obj", "x": 0.5}]}, path=tmp_path / "p.toml")
    raw = scaled_preset(preset, {"seafloor.roughness": 2.0, "seafloor.albedo": 1.8, "sonar.intensity": 3.0,
                                 "sonar.elevation": 1.5})
    assert raw["seafloor"]["rms_height"] == {"normal": [0.02, 0.004]}
    assert raw["seafloor"]["ripple_amplitude"] == {"choice": [0.0, 0.02]}
    assert raw["seafloor"]["albedo"] == {"uniform": [0.72, 1.0]}  # capped: albedo stays a reflectance
    assert raw["sonar"]["intensity"] == 3.0 and raw["sonar"]["max_range"] == 90.0  # defaults scaled too
    assert raw["targets"][0]["mesh"] == str(mesh)
    Preset.from_dict(raw)
    kinds = scaled_preset(load_preset("seafloor_mixed"), {"seafloor.roughness": 2.0})["seafloor"]
    assert [k["rms_height"] for k in kinds] == [{"uniform": [0.008, 0.04]}] * 3  # every [[seafloor]] kind alike
    assert [k.get("ripple_amplitude") for k in kinds] == [{"uniform": [0.1, 0.3]}, {"choice": [0.01, 0.02]}, 0.0]

    scenes = [preset.sample(0, i) for i in range(3)]
    low, high = scale_bounds(scenes, ("seafloor.albedo", "sonar.elevation"))
    assert high[0] == pytest.approx(1 / max(s.seafloor.albedo for s in scenes))
    assert low[1] == pytest.approx(max(s.sonar.near_range + 6.0 for s in scenes) / 60.0)


@pytest.mark.parametrize("path", sorted((REPO / "scenes").glob("*.toml")), ids=lambda p: p.stem)
def test_preset_toml_round_trips(path):
    import tomllib

    raw = tomllib.loads(path.read_text())
    assert tomllib.loads(preset_toml(raw)) == raw


def test_bad_params_name():
    with pytest.raises(SasmiError, match="allowed: seafloor.roughness, seafloor.albedo, sonar.intensity"):
        parse_params("seafloor.roughness,target.yaw")
    assert parse_params(" sonar.elevation , seafloor.albedo") == ("sonar.elevation", "seafloor.albedo")


def test_roughness_of_a_flat_floor_is_refused_and_a_rippled_one_has_relief(encoder):
    target = np.zeros((2, 1024))
    with pytest.raises(SasmiError, match="seafloor.roughness: the preset's seafloor is flat"):
        fit_scene(relief_preset(0.0, 0.0), encoder, target, FitConfig(steps=1, scenes=2, size=SIZE, spp=1))
    assert relief_preset(0.0, 0.01).sample(0, 0).seafloor.has_relief  # ripples alone are relief too


def test_bad_params_on_the_command_line(tmp_path, capsys):
    out = tmp_path / "fit"
    argv = ["fit-scene", str(REPO / "scenes" / "seafloor_only.toml"), "--phi", str(tmp_path), "--real",
            str(tmp_path), "--params", "seafloor.rougness", "--out", str(out)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "seafloor.rougness" in err and "allowed: seafloor.roughness" in err, err
    assert not out.exists()


def test_fit_scene_command(tmp_path, capsys):
    """render → train φ → fit-scene → the fitted preset renders; everything at 32² for speed."""
    import tomli_w

    truth, start = tmp_path / "truth.toml", tmp_path / "start.toml"
    truth.write_text(tomli_w.dumps(relief_preset().raw))
    start.write_text(tomli_w.dumps(relief_preset(0.01, 0.005).raw))
    real, ae, fit = tmp_path / "real", tmp_path / "ae", tmp_path / "fit"
    assert main(["render", str(truth), "--count", "2", "--size", "32", "--spp", "2", "--out", str(real)]) == 0
    assert main(["train", "autoencoder", "--real", str(real), "--out", str(ae), "--size", "32", "--batch", "2",
                 "--steps", "2", "--device", "cpu"]) == 0
    assert main(["fit-scene", str(start), "--phi", str(ae), "--real", str(real), "--params",
                 "seafloor.roughness,seafloor.albedo", "--steps", "3", "--scenes", "2", "--spp", "2",
                 "--out", str(fit)]) == 0
    lines = (fit / "trajectory.csv").read_text().splitlines()
    assert lines[0] == "step,loss,seafloor.roughness,seafloor.albedo" and len(lines) == 4
    assert (fit / "loss.png").stat().st_size > 0
    assert load_preset(fit / "fitted.toml").raw["seafloor"]["rms_height"] != 0.01
    capsys.readouterr()
    assert main(["render", str(fit / "fitted.toml"), "--count", "1", "--size", "16", "--spp", "1",
                 "--out", str(tmp_path / "again")]) == 0
    one = tmp_path / "one"  # a distribution of one chip: refused in one line, nothing written
    one.mkdir()
    (real / "images" / "000000.png").rename(one / "000000.png")
    assert main(["fit-scene", str(start), "--phi", str(ae), "--real", str(one), "--steps", "1", "--scenes", "2",
                 "--spp", "1", "--out", str(tmp_path / "fit1")]) == 2
    assert "--real" in capsys.readouterr().err
    assert not (tmp_path / "fit1").exists() or not any((tmp_path / "fit1").iterdir())


def test_ad_alone_gets_roughness_wrong_where_the_floor_shadows_itself(renderer):
    """Rough floor with a cylinder: Dr.Jit's AD alone gives d mean / d roughness the wrong sign (shadows grow
    with roughness, and AD does not see moving shadow edges), which is why roughness passes back a central
    difference of the image instead (right within 10 %: tests/realism/test_gradients.py)."""
    preset = Preset.from_dict({
        "sonar": {"near_range": 30.0, "emitters": 16},
        "seafloor": {"rms_height": 0.02, "correlation_length": 0.3, "ripple_amplitude": 0.01},
        "targets": [{"shape": "cylinder", "x": -0.8, "y": 0.2, "yaw": 60.0}],
        "post": {"speckle_looks": 0.0, "noise_std": 0.0}})
    scene = preset.sample(0, 0)
    bound = renderer.bind(scene, speckle=False)
    theta0 = scene_parameters(scene)
    theta = torch.tensor(theta0, dtype=torch.float32, requires_grad=True)
    renderer.image(bound, theta, 3, wrt=()).mean().backward()
    with torch.no_grad():
        fd = central_difference(lambda x: renderer.image(bound, torch.tensor(x), 3).mean().item(), theta0, 0, 0.03)
    assert theta.grad[0].item() / fd < 0  # AD alone: the wrong sign
