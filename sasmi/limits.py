"""The stated ranges of every number a user can give, each with the reason for its bound.

The one source of every range: FLAGS, keyed by a flag's name (one meaning in every command),
is read by the argparse types (sasmi/cli/arguments.py) and by the run configs that the flags
fill (gan/run.py's check_number), so a flag and the config it sets cannot disagree; SETTINGS
holds the recipe keys that have no flag; FIELDS, keyed by "section.field", the preset fields
(sasmi/scene/values.py). Lower bounds that are part of a preset field's meaning (> 0, in
[0, 1]) stay beside the field in sasmi/scene/model.py; this module adds the finite upper bounds
and why they are where they are.

A render costs ~0.5 kB of memory per pixel (1024 px: +0.5 GB for seafloor mesh, BVH and film),
whatever the spp, and takes ~5e6 samples (pixels x spp) per second on a 2-core AMD EPYC (AVX-512)
(docs/errors.md).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from sasmi.errors import SasmiError


def _number(v: float | None) -> str:
    """4294967295 stays whole, 1e-12 stays short."""
    if v is not None and float(v).is_integer() and abs(v) < 1e12:
        return str(int(v))
    return f"{v:g}" if v is not None else ""


@dataclass(frozen=True)
class Range:
    """lo <= value <= hi (ends optional); `kind` int or float; `why` explains the bound."""
    lo: float | None
    hi: float | None
    why: str
    kind: type = float
    multiple: int = 1  # ints only: value % multiple == 0

    def allowed(self) -> str:
        return f"{self.bounds()}; {self.why}" if self.why else self.bounds()

    def bounds(self) -> str:
        """The range alone, without its reason: "a multiple of 16, 16 to 4096"."""
        parts = []
        if self.kind is int and self.multiple > 1:
            parts.append(f"a multiple of {self.multiple}")
        lo, hi = _number(self.lo), _number(self.hi)
        if self.lo is not None and self.hi is not None:
            parts.append(f"{lo} to {hi}")
        elif self.lo is not None:
            parts.append(f">= {lo}")
        elif self.hi is not None:
            parts.append(f"<= {hi}")
        return ", ".join(parts) or "any finite number"

    def problem(self, value: float) -> str | None:
        """None if `value` is allowed, else why not (without the name)."""
        if isinstance(value, float) and not math.isfinite(value):
            return f"{value!r} is not a finite number"
        if self.lo is not None and value < self.lo or self.hi is not None and value > self.hi:
            return f"{value!r} is out of range"
        if self.kind is int and isinstance(value, int) and value % self.multiple:
            return f"{value!r} is not a multiple of {self.multiple}"
        return None

    def check(self, value: float, name: str) -> float:
        problem = self.problem(value)
        if problem:
            raise SasmiError(f"{name}: {problem} (allowed: {self.allowed()})")
        return value


# ---------------------------------------------------------------- sizes of things read whole

PRESET_MAX_BYTES = 1 << 20  # presets are a few kB; a cap stops /dev/zero or a stray data file being read whole
MESH_MAX_BYTES = 256 << 20  # trimesh holds a mesh several times over in memory
IMAGE_MAX_BYTES = 1 << 30  # one image file; anything larger is not a chip
IMAGE_MAX_PIXELS = 8192 * 8192  # decoded pixels of one image: 256 MB as float32 (chips are 128-1024 px)
MAX_TARGETS = 1024  # targets in one scene: each is a ~130-triangle mesh built per scene (144 take 3 ms)

# ---------------------------------------------------------------- command-line flags

MAX_SIZE = 4096
TRAIN_MAX_SIZE = 1024  # every image of a training set is held in memory at S²: 1000 images at 1024² are 4 GB
MAX_SAMPLES = 1 << 30  # size² x spp of one chip: ~4 min at ~5e6 samples/s; more is a typo, not a plan
SIZE_WHY = ("the critic, the autoencoder and the U-Net halve the image four times; a render costs ~0.5 kB per pixel "
            f"(~8 GB at {MAX_SIZE})")

FLAGS: dict[str, Range] = {
    "--seed": Range(0, 2**32 - 1, "numpy, torch and Dr.Jit all take seeds in [0, 2^32)", int),
    "--index": Range(0, 2**31 - 1, "scene numbers are non-negative", int),
    "--count": Range(1, 100_000, "every scene is drawn and checked before the first chip is written "
                                 "(up to 3 ms each) and each chip is 3 files in one folder; split larger sets "
                                 "by --seed", int),
    "--size": Range(16, MAX_SIZE, SIZE_WHY, int, multiple=16),
    "--spp": Range(1, 4096, "render time grows linearly with samples per pixel", int),
    "--workers": Range(1, 64, "each worker process holds its own Dr.Jit kernel and scene; "
                              "more processes than cores only wait", int),
    "--per-shard": Range(1, 100_000, "samples per tar shard; a shard is rendered whole before it is written", int),
    "--minutes": Range(0.01, 7 * 24 * 60, "a fraction of a minute is a smoke test in which every stage still runs; "
                                          "a week is the most any plan needs"),
    "--trials": Range(1, 1_000_000, "search trials; each renders --chips scenes", int),
    "--chips": Range(8, 4096, "renders scored per trial; medians of fewer than 8 move with every draw", int),
    "--refine-steps": Range(0, 10_000, "gradient steps after the search; each renders 8 scenes with their gradients", int),
    "--batch": Range(1, 1024, "one pass holds batch x size² activations per layer", int),
    "--steps": Range(1, 10_000_000, "training and fitting steps; 10^7 is weeks of GPU time", int),
    "--lr": Range(1e-8, 1.0, "Adam learning rates above 1 diverge at once; below 1e-8 float32 weights do not move"),
    "--critic-lr": Range(1e-8, 1.0, "as --lr"),
    "--betas": Range(0.0, 0.9999, "Adam's moment decays lie in [0, 1); nearer 1 they average over more steps "
                                  "than a run has"),
    "--checkpoint-every": Range(1, 10_000_000, "steps between checkpoints; a kill loses at most this many", int),
    "--n-critic": Range(1, 100, "critic updates per generator update; WGAN-GP uses 5", int),
    "--gp-weight": Range(0.0, 1e4, "λ of the gradient penalty; WGAN-GP uses 10"),
    "--r1-gamma": Range(0.0, 1e4, "γ of R1; StyleGAN2 uses 0.01-100"),
    "--phi-weight": Range(0.0, 1e6, "weight of the φ loss; the default is 100"),
    "--phi-margin": Range(0.0, 10.0, "free relative φ change, a fraction of ‖φ(render)‖; 10 means φ is not "
                                     "constrained at all"),
    "--ema": Range(0.0, 0.99999, "decay of the generator's moving average; 0 turns it off"),
    "--mask-weight": Range(0.0, 1e6, "weight of the mask contrast term; 0 turns it off"),
    "--mask-keep": Range(0.0, 2.0, "a fraction of the render's own contrast"),
    "--seeds": Range(1, 100, "each seed is one more training per regime", int),
    "--real-per-class": Range(0, 100_000, "real training chips drawn per class; 0 uses no real target, "
                                          "'all' every chip", int),
    "--bootstrap": Range(2, 100_000, "a ± needs 2 resamples; each resample recomputes one FID", int),
    "--scenes": Range(1, 256, "scenes rendered per fit step; time grows linearly", int),
    "--columns": Range(1, 256, "tiles per row of a contact sheet", int),
    "--limit": Range(1, 10_000, "tiles in one contact sheet, all held in memory", int),
}

# recipe keys with no flag of their own (gan/recipes/*.toml), checked by the run configs as the flags are
SETTINGS: dict[str, Range] = {
    "final_samples": Range(0, 100_000, "images the DCGAN writes when it ends", int),
    "mask_ring": Range(1, MAX_SIZE // 2, "pixels of floor around a shadow or target; below half the chip", int),
    "best_from": Range(0, 10_000_000, "best.pt is chosen at or after this step", int),
    "sample_every": Range(1, 10_000_000, "steps between sample grids", int),
    "log_every": Range(1, 10_000_000, "steps between TensorBoard scalars", int),
    "mask_rise": Range(0.0, 2.0, "signed units: the whole range is 2"),
    "shadow_weight": Range(0.0, 1e6, "weight of the shadow shape term; 0 turns it off"),
    "levels_weight": Range(0.0, 1e6, "weight of the gray-level term; 0 turns it off"),
    "augment.translation": Range(0.0, 0.5, "a fraction of the chip; beyond half the target leaves it"),
    "augment.cutout": Range(0.0, 1.0, "a fraction of the chip"),
    "augment.brightness": Range(0.0, 1.0, "in the signed range"),
    "augment.contrast": Range(0.0, 1.0, "a fraction of the contrast"),
    "generator.correction_scale": Range(1, 16, "px over which the correction is smooth; the small net's "
                                               "coarsest map is 16 px", int),
    "generator.donor_shadow": Range(0.0, 1.0, "a fraction of the median gray level"),
}


def setting_range(name: str) -> Range:
    """The range of a flag ("--lr") or a recipe key without one ("augment.cutout")."""
    return FLAGS[name] if name in FLAGS else SETTINGS[name]


def check_render_cost(size: int, spp: int, flags: str = "--size and --spp") -> None:
    """size² x spp within MAX_SAMPLES: render time grows with the product, not with each alone."""
    if size * size * spp > MAX_SAMPLES:
        raise SasmiError(f"{flags}: {size}² x {spp} = {size * size * spp:.3g} samples per chip (allowed: "
                         f"<= {MAX_SAMPLES:.3g}, ~4 min per chip at ~5e6 samples/s; lower --spp or --size)")


# ---------------------------------------------------------------- preset fields

ANGLE = Range(-360.0, 360.0, "degrees; one turn either way reaches every direction")
METRES = 1000.0  # no length in a chip scene needs more than a kilometre
GENERIC = Range(-1e6, 1e6, "no preset quantity needs more; larger values overflow the float32 geometry")
RELATIVE_LEVEL = Range(1e-6, 100.0, "a gray-level scale (1: flat albedo-1 sand at the chip centre is white); "
                                    "below 1e-6 every pixel is black, above 100 white")

FIELDS: dict[str, Range] = {
    "sonar.max_range": Range(None, 2000.0, "m; SAS ranges reach a few hundred metres, and the float32 ray "
                                           "tracer works in chip units"),
    "sonar.near_range": Range(None, 2000.0, "m; as max_range"),
    "sonar.chip_size": Range(0.1, 500.0, "m; below 0.1 m the chip-unit scale overflows the geometry, "
                                         "above 500 m a pixel is coarser than any target"),
    "sonar.track_length": Range(None, 5000.0, "m; the emitters are spread along it, a longer track only thins them"),
    "sonar.emitters": Range(None, 1024, "render time grows linearly with emitters (one spot light each)", int),
    "sonar.intensity": RELATIVE_LEVEL,
    "seafloor.rms_height": Range(None, 10.0, "m; the array flies at max_range / 10"),
    "seafloor.correlation_length": Range(1e-3, METRES, "m; beyond these the roughness is finer than a pixel or "
                                                               "flatter than a chip"),
    "seafloor.spectral_exponent": Range(None, 20.0, "steeper spectra are indistinguishable from smooth"),
    "seafloor.ripple_amplitude": Range(None, 10.0, "m; the array flies at max_range / 10"),
    "seafloor.ripple_wavelength": Range(1e-3, METRES, "m; as correlation_length"),
    "seafloor.ripple_direction": ANGLE,
    "seafloor.ripple_sinuosity": Range(None, 10.0, "wavelengths; crests that wander further are noise"),
    "seafloor.ripple_sharpness": Range(None, 100.0, "sharper crests are spikes narrower than the floor's samples"),
    "seafloor.mosaic_contrast": Range(1e-3, 1e3, "a sediment 1000 times weaker than the other renders black"),
    "seafloor.mosaic_size": Range(None, METRES, "m; as correlation_length"),
    "seafloor.rocks": Range(None, 1000, "each rock is one pass over the (size+1)² heightfield "
                                        "(~0.4 ms at 256 px)", int),
    "seafloor.rock_radius": Range(None, 100.0, "m; a larger bump is the seafloor, not clutter"),
    "targets.yaw": ANGLE,
    "targets.burial": Range(None, 100.0, "m; deeper than any target is tall"),
    "targets.length": Range(None, 100.0, "m; longer than any chip's target"),
    "targets.radius": Range(None, 100.0, "m; as length"),
    "targets.radius_top": Range(None, 100.0, "m; as length"),
    "targets.width": Range(None, 100.0, "m; as length"),
    "targets.height": Range(None, 100.0, "m; as length"),
    "targets.tube_radius": Range(None, 100.0, "m; as length"),
    "targets.scale": Range(None, 1000.0, "a mesh file's units to metres (mm -> m is 0.001)"),
    "post.gain": RELATIVE_LEVEL,
    "post.speckle_looks": Range(None, 1000.0, "gamma speckle with more looks is indistinguishable from none"),
    "post.noise_std": Range(None, 10.0, "gray levels; images are in [0, 1]"),
    "target_grid.spacing": Range(0.01, METRES, "m; the target count is bounded separately"),
    "target_grid.jitter": Range(None, 100.0, "m; larger offsets only pile targets on the chip edge"),
}
MAX_STRING = 4096  # characters in a preset string (a mesh path, a description)
MAX_CHOICES = 10_000  # entries of one {choice = [...]}


def field_range(section: str, name: str) -> Range:
    """The range of preset field `section.name` ("targets" for every target); GENERIC if not listed."""
    return FIELDS.get(f"{section}.{name}", GENERIC)


def markdown_table() -> str:
    """Every range as the table docs/errors.md carries."""
    rows = ["| flag, recipe key or preset field | allowed | why |", "|---|---|---|"]
    for table in (FLAGS, SETTINGS, FIELDS):
        rows += [f"| `{name}` | {r.bounds()} | {r.why} |" for name, r in table.items()]
    return "\n".join(rows) + "\n"
