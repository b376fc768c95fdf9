"""Losses as pure functions of scores, images and features; the training loop weights them.

WGAN-GP (Gulrajani et al. 2017): the critic maximises mean D(real) − mean D(fake) while
a penalty keeps its gradient norm near 1 at random interpolates, λ = 10. The alternative
is StyleGAN2's pair: the non-saturating logistic loss with the R1 penalty on real images
(Mescheder et al. 2018); R1 needs the logistic loss, since under the Wasserstein loss
nothing would bound the fake scores. The SAS GAN adds the φ constraint of Reed et al.
(the generator may change an image's φ only by a margin), a mask-driven contrast term and a
mask-driven shadow shape term.
"""
from __future__ import annotations

from typing import Callable

import torch
import torch.nn.functional as F


def critic_loss(real_scores: torch.Tensor, fake_scores: torch.Tensor) -> torch.Tensor:
    """Negative Wasserstein estimate; (B,) scores → scalar. Minimised by the critic."""
    return fake_scores.mean() - real_scores.mean()


def generator_loss(fake_scores: torch.Tensor) -> torch.Tensor:
    """(B,) scores of generated images → scalar. Minimised by the generator."""
    return -fake_scores.mean()


def gradient_penalty(critic: Callable[[torch.Tensor], torch.Tensor], real: torch.Tensor,
                     fake: torch.Tensor, alpha: torch.Tensor) -> torch.Tensor:
    """mean over the batch of (‖∇ₓ D(x̂)‖₂ − 1)², x̂ = α·real + (1 − α)·fake.

    real, fake: (B, 1, S, S); alpha: (B, 1, 1, 1) in [0, 1], drawn by the caller so that
    its random stream belongs to the run's resumable state. Differentiable with respect
    to the critic's weights (create_graph), which is what trains the critic.
    """
    assert real.shape == fake.shape and alpha.shape == (real.shape[0], 1, 1, 1), (real.shape, fake.shape, alpha.shape)
    x = (alpha * real + (1.0 - alpha) * fake).requires_grad_(True)
    (grad,) = torch.autograd.grad(critic(x).sum(), x, create_graph=True)
    return ((grad.flatten(1).norm(dim=1) - 1.0) ** 2).mean()


def logistic_critic_loss(real_scores: torch.Tensor, fake_scores: torch.Tensor) -> torch.Tensor:
    """Non-saturating GAN, critic side: mean softplus(D(fake)) + mean softplus(−D(real)); (B,) → scalar."""
    return F.softplus(fake_scores).mean() + F.softplus(-real_scores).mean()


def logistic_generator_loss(fake_scores: torch.Tensor) -> torch.Tensor:
    """Non-saturating GAN, generator side: mean softplus(−D(G(·))); (B,) → scalar."""
    return F.softplus(-fake_scores).mean()


def r1_penalty(critic: Callable[[torch.Tensor], torch.Tensor], real: torch.Tensor) -> torch.Tensor:
    """mean over the batch of ‖∇ₓ D(x)‖₂² at the real images (B, 1, S, S); the caller weights it by γ/2."""
    x = real.detach().requires_grad_(True)
    (grad,) = torch.autograd.grad(critic(x).sum(), x, create_graph=True)
    return grad.flatten(1).pow(2).sum(dim=1).mean()


def phi_loss(phi_a: torch.Tensor, phi_b: torch.Tensor, margin: float) -> torch.Tensor:
    """Hinge on the relative φ distance: mean over the batch of max(0, ‖φa − φb‖ / ‖φa‖ − γ).

    phi_a: (B, D) of the renders, phi_b: (B, D) of the generated images. Zero while the
    generator stays within γ of the render's φ (Reed et al.'s constraint), linear beyond.
    Dividing by ‖φa‖ makes γ a fraction (0.25 = a quarter of the render's φ norm) that
    does not depend on the scale a particular autoencoder run happened to learn.
    """
    assert phi_a.shape == phi_b.shape and phi_a.ndim == 2, (phi_a.shape, phi_b.shape)
    distance = (phi_b - phi_a).norm(dim=1) / phi_a.norm(dim=1).clamp_min(1e-8)
    return (distance - margin).clamp_min(0.0).mean()


def phi_distribution_loss(phi: torch.Tensor, real_mean: torch.Tensor, real_spread: torch.Tensor,
                          spread_weight: float) -> torch.Tensor:
    """How far a set's φ distribution lies from the real chips': the distance between the mean φ
    vectors relative to the real mean's norm, plus `spread_weight` times the relative difference of
    the spreads (the root mean over features of the variance across chips).

    phi: (K, D) of K ≥ 2 chips; real_mean, real_spread: (D,), the real chips' mean and standard
    deviation per feature. The set's variances are unbiased (K − 1), and their mean over D features
    has little noise even for a few chips; the norm of per-feature differences would not do: with 4
    chips each feature's spread is 40 % noise, and a fit minimising that norm shrinks the spread.
    The mean alone cannot pin what changes how chips differ from each other but not their average.
    """
    assert phi.ndim == 2 and len(phi) >= 2 and real_mean.shape == real_spread.shape == phi.shape[1:], \
        (phi.shape, real_mean.shape, real_spread.shape)
    mean_term = (phi.mean(0) - real_mean).norm() / real_mean.norm().clamp_min(1e-8)
    spread, real = phi.var(0).mean().sqrt(), real_spread.pow(2).mean().sqrt().clamp_min(1e-8)
    return mean_term + spread_weight * (spread - real).abs() / real


def reconstruction_loss(reconstruction: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Mean squared error (the autoencoder's L2), images in [-1, 1]."""
    return ((reconstruction - target) ** 2).mean()


def floor_near(region: torch.Tensor, masks: torch.Tensor, ring: int) -> torch.Tensor:
    """The seafloor (mask 0) within `ring` px of `region`: (B, 1, S, S) bool."""
    return F.max_pool2d(region.float(), 2 * ring + 1, stride=1, padding=ring).bool() & (masks == 0)


def mask_contrasts(images: torch.Tensor, masks: torch.Tensor, ring: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Per image: (floor − shadow, target − floor) mean brightness, each (B,), NaN where absent.

    images: (B, 1, S, S) in [-1, 1]; masks: (B, 1, S, S) labels 0 seafloor, 1 target, 2 shadow.
    "floor" is the seafloor within `ring` px of the shadow (for the first) or of the target
    (for the second): the local background the eye compares them with.
    """
    def mean(region: torch.Tensor) -> torch.Tensor:
        n = region.sum(dim=(1, 2, 3))
        total = (images * region).sum(dim=(1, 2, 3))
        return torch.where(n > 0, total / n.clamp_min(1), torch.full_like(total, float("nan")))

    shadow, target = masks == 2, masks == 1
    return (mean(floor_near(shadow, masks, ring)) - mean(shadow),
            mean(target) - mean(floor_near(target, masks, ring)))


def highlight_peaks(images: torch.Tensor, masks: torch.Tensor, bright_percentile: float = 99.0) -> torch.Tensor:
    """Per image: how far the target's brightest spot rises above the floor's bright speckle, (B,), NaN if absent.

    images: (B, 1, S, S) in [-1, 1]; masks as in `mask_contrasts`. On the image blurred over
    3 × 3 px: the mean of the 4 brightest target pixels minus the `bright_percentile` of the
    whole seafloor, the floor's level detached (the term raises highlights, it never dims the
    floor). Below 0 the target has nothing brighter than the floor's speckle: the test by
    which `sasmi evaluate` calls a target lost (sasmi/eval/preservation.py).
    """
    blurred = F.avg_pool2d(images, 3, stride=1, padding=1, count_include_pad=False)
    peaks = []
    for image, mask in zip(blurred, masks):
        target, floor = image[mask == 1], image[mask == 0]
        if target.numel() == 0 or floor.numel() == 0:
            peaks.append(image.sum() * 0.0 + float("nan"))
            continue
        top = target.topk(min(4, target.numel())).values.mean()
        peaks.append(top - torch.quantile(floor.detach(), bright_percentile / 100.0))
    return torch.stack(peaks)


def mask_contrast_loss(fake: torch.Tensor, render: torch.Tensor, masks: torch.Tensor, keep: float,
                       ring: int, highlight: str = "mean", least_rise: float = 0.0) -> torch.Tensor:
    """Hinge keeping shadows darker and highlights brighter than the floor around them.

    For each image and each of (shadow, highlight) present in its mask: max(0, keep·c_render
    − c_fake), c the contrast of `mask_contrasts`; mean over the terms present (0 if none).
    fake, render: (B, 1, S, S) in [-1, 1]; masks: the render's labels. keep = 0.5 lets the
    generator halve a render's shadow contrast for free but not erase or invert it.
    highlight = "peak" measures the highlight by `highlight_peaks` instead of the target's mean:
    a thin bright strip on a bright floor keeps its rise above the floor's speckle.
    least_rise (signed units) is the highlight contrast asked of every target whatever its render's:
    a target the render leaves at or under the floor's speckle (lost) is raised out of it, where
    `keep` × its clamped contrast (0) asks it only to reach the speckle.
    """
    def contrasts(images: torch.Tensor) -> torch.Tensor:  # (2, B)
        shadow, target = mask_contrasts(images, masks, ring)
        return torch.stack([shadow, highlight_peaks(images, masks) if highlight == "peak" else target])

    with torch.no_grad():
        wanted = contrasts(render).clamp_min(0) * keep
        wanted[1] = wanted[1].clamp_min(least_rise)
    got = contrasts(fake)
    present = ~torch.isnan(got)
    if not present.any():
        return fake.sum() * 0.0  # keeps the graph; no shadow or target in this batch
    return (wanted[present] - got[present]).clamp_min(0.0).mean()


def shadow_outline(images: torch.Tensor, masks: torch.Tensor, ring: int, smooth: float = 1.5,
                   dark_fraction: float = 0.5, softness: float = 0.1) -> tuple[torch.Tensor, torch.Tensor]:
    """Per image: (dark seafloor beside the shadow, pale shadow), each in shadow areas, (B,), NaN without shadow.

    images: (B, 1, S, S) in [-1, 1]; masks as in `mask_contrasts`. The evaluation's "dark"
    (sasmi/eval/preservation.py) with its hard threshold made a sigmoid: on the image in [0, 1]
    blurred by `smooth` px, a pixel is dark by sigmoid((dark_fraction·m − s) / (softness·m)), m the
    median of the seafloor (detached). "Beside": the darkness summed over the seafloor within `ring`
    px of the shadow or target (a shadow widened by its own width on each side scores 2); "pale":
    the shadow's pixels not dark. Each lowers the evaluation's shadow IoU.
    """
    radius = max(1, round(3 * smooth))
    taps = torch.exp(-0.5 * (torch.arange(-radius, radius + 1, device=images.device) / smooth) ** 2)
    taps = (taps / taps.sum()).to(images)
    s = F.pad((images + 1) / 2, (radius,) * 4, mode="reflect")
    s = F.conv2d(F.conv2d(s, taps.view(1, 1, 1, -1)), taps.view(1, 1, -1, 1))  # (B, 1, S, S) in [0, 1]
    floor, shadow = masks == 0, masks == 2
    level = torch.where(floor, s.detach(), torch.full_like(s, float("nan"))).flatten(1).nanmedian(dim=1).values
    level = level.clamp_min(1e-3).view(-1, 1, 1, 1)
    dark = torch.sigmoid((dark_fraction * level - s) / (softness * level))
    beside = floor_near(masks > 0, masks, ring)  # (B, 1, S, S)
    area = shadow.sum(dim=(1, 2, 3))
    nan = torch.full(area.shape, float("nan"), dtype=images.dtype, device=images.device)

    def per_shadow_area(x: torch.Tensor) -> torch.Tensor:
        return torch.where(area > 0, x.sum(dim=(1, 2, 3)) / area.clamp_min(1), nan)

    return per_shadow_area(dark * beside), per_shadow_area((1 - dark) * shadow)


def shadow_shape_loss(fake: torch.Tensor, render: torch.Tensor, masks: torch.Tensor, ring: int) -> torch.Tensor:
    """Each shadow's outline kept at its render's: over the images with a shadow, the mean of
    |beside(fake) − beside(render)| + |pale(fake) − pale(render)| (`shadow_outline`).

    fake, render: (B, 1, S, S) in [-1, 1]. The contrast term keeps a shadow darker than the floor
    around it, and is met as well when that floor darkens too: the shadow widens (docs/gan.md,
    *Why each part*). Two terms, not one on a soft IoU: asked for the render's IoU, where darker
    inside buys wider outside, the generator makes shadows darker than real ones. Two-sided, not
    hinges: a hinge on a noisy per-chip figure is met with a margin, and the generator learns
    shadows darker than the render's with a bright rim beside them.
    """
    with torch.no_grad():
        allowed = torch.stack(shadow_outline(render, masks, ring))  # (2, B)
    got = torch.stack(shadow_outline(fake, masks, ring))
    present = ~torch.isnan(got[0])  # (B,): the images with a shadow
    if not present.any():
        return fake.sum() * 0.0  # keeps the graph; no shadow in this batch
    return (got[:, present] - allowed[:, present]).abs().mean(dim=1).sum()  # beside + pale


LEVEL_QUANTILES = torch.linspace(0.02, 0.98, 25)  # and the tail: 0.99, 0.995
LEVEL_TAIL = torch.tensor([0.99, 0.995])


def gray_levels(images: torch.Tensor) -> torch.Tensor:
    """Each chip's gray-level distribution as 27 of its quantiles, the bright tail included:
    (B, 1, S, S) in [-1, 1] → (B, 27). Differentiable (through the sort)."""
    q = torch.cat([LEVEL_QUANTILES, LEVEL_TAIL]).to(images)
    return torch.quantile(images.flatten(1), q, dim=1).T


DISTANCE_ROWS = 64


def energy_distance(x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
    """Energy distance between two samples of vectors, x (n, D) and y (m, D), n, m ≥ 2:
    2 E‖x − y‖ − E‖x − x′‖ − E‖y − y′‖ (Székely & Rizzo), the within-sample means over distinct
    pairs. Zero in expectation when both come from one distribution, no bandwidth to choose."""
    assert x.ndim == y.ndim == 2 and x.shape[1] == y.shape[1] and len(x) > 1 and len(y) > 1, (x.shape, y.shape)

    def mean_distance(a: torch.Tensor, b: torch.Tensor, distinct: bool) -> torch.Tensor:
        total = a.new_zeros(())
        for i in range(0, len(a), DISTANCE_ROWS):  # (rows, m, D) at a time: 20000 chips fit in memory
            d = (a[i:i + DISTANCE_ROWS, None] - b[None]).pow(2).sum(-1).clamp_min(1e-12).sqrt()  # clamp: no NaN gradient at 0
            if distinct:  # leave out each chip's distance to itself
                rows = torch.arange(len(d), device=d.device)
                d = d.index_put((rows, rows + i), d.new_zeros(len(d)))
            total = total + d.sum()
        return total / (len(a) * (len(a) - 1) if distinct else len(a) * len(b))

    return 2 * mean_distance(x, y, False) - mean_distance(x, x, True) - mean_distance(y, y, True)
