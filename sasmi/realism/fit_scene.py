"""Fit scene parameters to real chips by gradient descent through the differentiable render.

The loop renders K scenes of a preset with the current parameters, encodes them with the
GAN's φ encoder and pulls the φ distribution of the renders (mean and spread) towards that
of the real chips; the gradient reaches the parameters through `DifferentiableRenderer` (AD;
central differences of the image for roughness and elevation, which move shadow edges). What moves
is a scale factor per parameter, 1 = the preset, so a preset whose fields are distributions
keeps its spread and the fitted preset scales each field (docs/differentiable.md):

    seafloor.roughness  rough + ripple relief        → seafloor.rms_height, seafloor.ripple_amplitude
    seafloor.albedo     floor reflectance (≤ 1)      → seafloor.albedo
    sonar.intensity     source level                 → sonar.intensity
    sonar.elevation     altitude of the array        → sonar.altitude if set, else sonar.max_range

Adam works on the log-scales: relative steps, always positive. The loss is
`phi_distribution_loss`: by the mean alone, roughness (how much the floor shades, which changes
how chips differ more than their average) ends where it starts (docs/differentiable.md, *Loss*).
The renders keep the preset's speckle and noise, fields fixed per scene: real chips have speckle.
"""
from __future__ import annotations

import contextlib
import copy
import csv
import io
import json
import math
import os
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
from tqdm import tqdm

from sasmi.errors import SasmiError
from sasmi.images import list_images, write_text
from sasmi.preprocess import check_size
from sasmi.render.differentiable import PARAMETERS
from sasmi.scene.preset import SECTIONS, Preset
from sasmi.scene.model import Scene

# preset fields each parameter scales: (section, key)
PRESET_FIELDS = {
    "seafloor.roughness": (("seafloor", "rms_height"), ("seafloor", "ripple_amplitude")),
    "seafloor.albedo": (("seafloor", "albedo"),),
    "sonar.intensity": (("sonar", "intensity"),),
    "sonar.elevation": (("sonar", "max_range"),),
}
SCALE_LIMIT = 1e3  # scales stay in [1/SCALE_LIMIT, SCALE_LIMIT]; beyond that a fit has gone wrong anyway


@dataclass(frozen=True)
class FitConfig:
    params: tuple[str, ...] = ("seafloor.roughness",)  # what moves; everything else keeps the preset's value
    steps: int = 50  # Adam updates
    lr: float = 0.05  # on log-scales: at most ~5 % change per step; decays (cosine) to lr / 10 at the end
    betas: tuple[float, float] = (0.5, 0.9)  # Adam's; with β1 = 0.9 a fit of a few dozen steps overshoots and still rings at its end
    # scenes 0..K-1 of the preset, all rendered every step; their φ distribution is matched. With 4, which
    # scenes were drawn moves a fitted roughness by about 20 %; with 8, 12 % (docs/results.md)
    scenes: int = 8
    spread_weight: float = 1.0  # the spreads' term beside the means'; 0: the mean φ alone
    size: int | None = None  # render size; None: the size the φ encoder was trained at (real chips are 128²)
    spp: int = 8  # samples per pixel of each render (and of its gradient)
    seed: int = 0  # preset draws (scene i = preset.sample(seed, i)); sampler seeds follow from it and the step
    speckle: bool = True  # the preset's speckle and noise as fixed per-scene fields: real chips have speckle

    def validate(self) -> "FitConfig":
        check_params(self.params)
        for name, value, low in (("steps", self.steps, 1), ("scenes", self.scenes, 2), ("spp", self.spp, 1)):
            if value < low:
                raise SasmiError(f"--{name}: {value} is not allowed (allowed: >= {low})")
        if self.size is not None:
            check_size(self.size, "--size")
        if not self.lr > 0:
            raise SasmiError(f"--lr: {self.lr} is not allowed (allowed: > 0)")
        if not self.spread_weight >= 0:
            raise SasmiError(f"--spread-weight: {self.spread_weight} is not allowed (allowed: >= 0)")
        return self

    def for_encoder(self, encoder) -> "FitConfig":
        """This config with the render size settled: the encoder's training size unless set."""
        return replace(self, size=self.size or encoder.image_size)


@dataclass(frozen=True)
class FitResult:
    params: tuple[str, ...]
    scales: dict[str, float]  # final scale per fitted parameter (1 = the preset)
    trajectory: list[dict]  # per step: step, loss, and the scales the loss was computed at
    seconds_per_step: float


def check_params(params: Sequence[str]) -> tuple[str, ...]:
    unknown = [p for p in params if p not in PARAMETERS]
    if unknown or not params:
        what = f"unknown parameter {', '.join(unknown)}" if unknown else "no parameter given"
        raise SasmiError(f"--params: {what} (allowed: {', '.join(PARAMETERS)})")
    if len(set(params)) != len(params):
        raise SasmiError(f"--params: {', '.join(params)} names a parameter twice")
    return tuple(params)


def parse_params(text: str) -> tuple[str, ...]:
    """'seafloor.roughness,seafloor.albedo' → a checked tuple."""
    return check_params([p.strip() for p in text.split(",") if p.strip()])


# Scales ↔ preset

def _scale_value(value, scale: float, cap: float | None):
    """A preset value or distribution times `scale`, capped at `cap` (a distribution keeps its kind)."""
    def one(v: float) -> float:
        v = float(v) * scale
        return float(f"{min(v, cap) if cap is not None else v:.6g}")  # 6 digits: a preset people read

    if not isinstance(value, dict):
        return one(value)
    kind, args = next(iter(value.items()))
    if kind == "normal":
        return {kind: [one(args[0]), float(f"{float(args[1]) * scale:.6g}")]}
    return {kind: [one(a) for a in args]}


def scaled_preset(preset: Preset, scales: dict[str, float]) -> dict:
    """The preset's TOML dict with each scaled field multiplied by its parameter's scale.

    A field the preset leaves out is written with its default times the scale. Mesh paths
    become absolute, so the fitted preset works from wherever it is saved.
    """
    raw = copy.deepcopy(preset.raw)
    for name, scale in scales.items():
        fields = PRESET_FIELDS[name]
        if name == "sonar.elevation" and raw.get("sonar", {}).get("altitude"):
            fields = (("sonar", "altitude"),)  # an altitude of its own: max_range stays
        for section, key in fields:
            default = SECTIONS[section].__dataclass_fields__[key].default
            tables = raw[section] if isinstance(raw.get(section), list) else [raw.setdefault(section, {})]
            for table in tables:  # every [[seafloor]] kind alike
                table[key] = _scale_value(table.get(key, default), scale, 1.0 if name == "seafloor.albedo" else None)
    targets = raw.get("targets", []) + [raw.get("target_grid", {}).get("target", {})]
    for target in targets:
        if target.get("mesh"):
            target["mesh"] = str(preset.resolve_mesh(target["mesh"]).resolve())
    return raw


def scale_bounds(scenes: Sequence[Scene], params: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
    """(P,) lowest and highest scale per parameter that keeps every fitted scene valid (albedo <= 1)."""
    low = np.full(len(params), 1.0 / SCALE_LIMIT)
    high = np.full(len(params), SCALE_LIMIT)
    for i, name in enumerate(params):
        if name == "seafloor.albedo":
            high[i] = min(SCALE_LIMIT, 1.0 / max(s.seafloor.albedo for s in scenes))
        if name == "sonar.elevation":  # an altitude of max_range / 10: the chip must stay within range
            low[i] = max([(s.sonar.near_range + s.sonar.chip_size) / s.sonar.max_range
                          for s in scenes if not s.sonar.altitude] + [1.0 / SCALE_LIMIT])
    return low, high


# φ target, gradient checks

def real_phi(encoder, folder: str | os.PathLike, size: int, batch: int = 32) -> np.ndarray:
    """(N, D) float64 φ of the real chips in `folder`, brought to `size` as the GAN's training does."""
    import torch

    from sasmi.eval.features import load_images

    paths = list_images(folder)
    if not paths:
        raise SasmiError(f"{folder}: no images (png, jpg, tif, tiff, npy) in it")
    images = torch.from_numpy(load_images(paths, size))[:, None] * 2.0 - 1.0  # (N, 1, S, S) in [-1, 1]
    with torch.no_grad():
        phi = torch.cat([encoder(images[i:i + batch]) for i in range(0, len(images), batch)])  # (N, D)
    return phi.double().numpy()


def central_difference(f: Callable[[np.ndarray], float], x: np.ndarray, index: int, step: float) -> float:
    """(f(x + h e_i) − f(x − h e_i)) / 2h: the reference the AD gradients are checked against."""
    plus, minus = np.array(x, dtype=np.float64), np.array(x, dtype=np.float64)
    plus[index] += step
    minus[index] -= step
    return (f(plus) - f(minus)) / (2 * step)


# The fit

@contextlib.contextmanager
def one_torch_thread():
    """Context: torch on one thread. The encoder is small and Dr.Jit keeps its own pool busy;
    torch threads waiting for a core make the encoder many times slower."""
    import torch

    previous = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(previous)


def sampler_seed(seed: int, step: int, scene: int) -> int:
    """A fresh Monte Carlo sample stream for every step and scene, so no step's noise is fitted."""
    return int(np.random.SeedSequence([seed, step, scene]).generate_state(1)[0] >> 1)

def fit_scene(preset: Preset, encoder, target_phi: np.ndarray, cfg: FitConfig, progress: bool = True) -> FitResult:
    """Adam on the log-scales of `cfg.params` so that the φ of K renders is distributed as `target_phi`
    (N, D), the φ of N ≥ 2 real chips."""
    import torch

    from sasmi.gan.losses import phi_distribution_loss
    from sasmi.render.differentiable import DifferentiableRenderer, scene_parameters

    cfg = cfg.for_encoder(encoder).validate()
    scenes = [preset.sample(cfg.seed, i) for i in range(cfg.scenes)]
    if "seafloor.roughness" in cfg.params and not any(s.seafloor.has_relief for s in scenes):
        raise SasmiError("seafloor.roughness: the preset's seafloor is flat (rms_height = ripple_amplitude = 0), "
                         "there is no relief to scale")
    renderer = DifferentiableRenderer(cfg.size, cfg.spp)
    bound = [renderer.bind(s, cfg.speckle) for s in scenes]
    theta0 = torch.tensor(np.stack([scene_parameters(s) for s in scenes]), dtype=torch.float32)  # (K, 4)
    index = torch.tensor([PARAMETERS.index(p) for p in cfg.params])
    low, high = (torch.tensor(np.log(b), dtype=torch.float32) for b in scale_bounds(scenes, cfg.params))
    target = torch.as_tensor(np.asarray(target_phi), dtype=torch.float64)  # (N, D)
    if target.ndim != 2 or len(target) < 2:
        raise SasmiError(f"the real chips' φ: {tuple(target.shape)}; a distribution needs at least 2 chips")
    real_mean, real_spread = target.mean(0).float(), target.std(0).float()  # (D,) each

    log_scale = torch.zeros(len(cfg.params), requires_grad=True)  # (P,); 0 = the preset
    opt = torch.optim.Adam([log_scale], lr=cfg.lr, betas=cfg.betas)
    schedule = torch.optim.lr_scheduler.CosineAnnealingLR(opt, T_max=cfg.steps, eta_min=cfg.lr / 10)
    trajectory = []
    start = time.perf_counter()
    bar = tqdm(range(cfg.steps), desc="fit-scene", unit="step", disable=not progress, dynamic_ncols=True)
    with one_torch_thread():
        for step in bar:
            # forward: K renders at θ0 · scale, their φ distribution against the real chips'
            scale = torch.ones(len(PARAMETERS)).index_put((index,), log_scale.exp())  # (4,)
            images = torch.stack([renderer.image(b, theta0[k] * scale, sampler_seed(cfg.seed, step, k), wrt=cfg.params)
                                  for k, b in enumerate(bound)])  # (K, S, S) in [0, 1]
            phi = encoder(images[:, None] * 2.0 - 1.0)  # (K, D)
            loss = phi_distribution_loss(phi, real_mean, real_spread, cfg.spread_weight)
            if not math.isfinite(loss.item()):
                raise SasmiError(f"step {step}: the loss is not finite (scales {scale.tolist()}); lower --lr")
            # backward, update, keep the scenes valid
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            schedule.step()
            with torch.no_grad():
                log_scale.copy_(torch.maximum(torch.minimum(log_scale, high), low))
            # log
            trajectory.append({"step": step, "loss": loss.item(),
                               **{p: float(s) for p, s in zip(cfg.params, scale[index].detach())}})
            bar.set_postfix(loss=f"{loss.item():.4g}")
    seconds = (time.perf_counter() - start) / cfg.steps
    final = {p: float(s) for p, s in zip(cfg.params, log_scale.detach().exp())}
    return FitResult(params=tuple(cfg.params), scales=final, trajectory=trajectory, seconds_per_step=seconds)


# Output: trajectory, loss curve, fitted preset

def preset_toml(raw: dict) -> str:
    """A preset dict as TOML laid out like scenes/*.toml: a [section] each, distributions inline."""
    import tomli_w

    def value(v) -> str:
        if isinstance(v, dict):  # a distribution, e.g. {uniform = [30.0, 50.0]}
            return "{" + ", ".join(f"{k} = {value(a)}" for k, a in v.items()) + "}"
        if isinstance(v, list):
            return "[" + ", ".join(value(a) for a in v) + "]"
        return tomli_w.dumps({"v": v})[len("v = "):].strip()  # TOML's own spelling of a number or string

    def table(header: str, t: dict) -> list[str]:
        return ["", header, *(f"{k} = {value(v)}" for k, v in t.items() if k != "target")]

    lines = [f"{k} = {value(v)}" for k, v in raw.items() if not isinstance(v, (dict, list))]
    for key, t in raw.items():
        if isinstance(t, list):  # [[targets]], [[seafloor]]
            lines += [line for kind in t for line in table(f"[[{key}]]", kind)]
        elif isinstance(t, dict):
            lines += table(f"[{key}]", t)
            if "target" in t:  # target_grid.target
                lines += table(f"[{key}.target]", t["target"])
    return "\n".join(lines) + "\n"


def trajectory_csv(result: FitResult) -> str:
    out = io.StringIO()
    writer = csv.DictWriter(out, fieldnames=["step", "loss", *result.params], lineterminator="\n")
    writer.writeheader()
    writer.writerows(result.trajectory)
    return out.getvalue()


def loss_figure(result: FitResult, path: Path) -> None:
    from matplotlib.figure import Figure

    from sasmi.eval.report import save_figure

    steps = [row["step"] for row in result.trajectory]
    fig = Figure(figsize=(9, 3.5))
    ax_loss, ax_scale = fig.subplots(1, 2)
    ax_loss.plot(steps, [row["loss"] for row in result.trajectory])
    ax_loss.set(xlabel="step", ylabel="relative φ distance (means + spreads)", yscale="log", title="loss")
    for name in result.params:
        ax_scale.plot(steps, [row[name] for row in result.trajectory], label=name)
    ax_scale.axhline(1.0, color="0.7", lw=0.8)
    ax_scale.set(xlabel="step", ylabel="scale (1 = preset)", title="parameters")
    ax_scale.legend()
    fig.tight_layout()
    save_figure(fig, path)


def write_fit(out: str | os.PathLike, preset: Preset, result: FitResult, record: dict) -> Path:
    """OUT/trajectory.csv, loss.png, fitted.toml (a preset `sasmi render` accepts) and fit_scene.json."""
    out = Path(out)
    raw = scaled_preset(preset, result.scales)
    Preset.from_dict(raw)  # a fit that cannot be rendered is a bug here, not a surprise later
    header = (f"# Fitted by `sasmi fit-scene` from {preset.path}: scales "
              + ", ".join(f"{p} x{s:.4g}" for p, s in result.scales.items()) + "\n")
    write_text(out / "trajectory.csv", trajectory_csv(result))
    loss_figure(result, out / "loss.png")
    write_text(out / "fitted.toml", header + preset_toml(raw))
    write_text(out / "fit_scene.json", json.dumps({**record, "scales": result.scales,
                                             "final_loss": result.trajectory[-1]["loss"],
                                             "seconds_per_step": result.seconds_per_step}, indent=2) + "\n")
    return out


def fit_to_real(preset_path: str | os.PathLike, phi_run: str | os.PathLike, real: str | os.PathLike,
                cfg: FitConfig, out: str | os.PathLike, progress: bool = True) -> Path:
    """One call: fit `cfg.params` of a preset so its renders' φ is distributed as the real chips'; write OUT."""
    from sasmi.gan.autoencoder import load_encoder
    from sasmi.render.llvm import versions
    from sasmi.scene.preset import load_preset

    cfg.validate()
    preset = load_preset(preset_path)
    encoder = load_encoder(phi_run)
    cfg = cfg.for_encoder(encoder)
    target = real_phi(encoder, real, cfg.size)
    if len(target) < 2:
        raise SasmiError(f"--real {real}: one chip; fit-scene matches a distribution of chips, give at least 2")
    result = fit_scene(preset, encoder, target, cfg, progress)
    record = {"preset": str(Path(preset_path).resolve()), "phi": str(Path(phi_run).resolve()),
              "real": str(Path(real).resolve()), "config": asdict(cfg), "versions": versions()}
    return write_fit(out, preset, result, record)
