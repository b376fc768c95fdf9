"""What tells a set of chips from the real ones: two probes, to decide where realism is lost.

1. φ sensitivity. The set's φ-FID ratio to the real chips (`sasmi evaluate`'s matched-size
   ratio) after transforms that each remove one kind of difference: blurring over 4 px
   (what the SAS GAN's smooth correction can reach; it also removes speckle), giving every
   chip the pooled real gray-level histogram, or each chip the histogram of one real chip
   drawn at random (rank-preserving: nothing moves, only levels). The real chips blurred
   are scored against themselves, to show what smoothing alone does to the ratio.
2. Separability. A small critic (the SAS GAN's, logistic loss, 400 steps) learns real vs
   set on the first 300 of the set and the real chips, per view (raw, blurred over 4 px,
   the speckle left after that blur, each chip standardised, its sorted gray levels only);
   its AUC on held-out real chips and the rest of the set says which view gives it away.

    .venv/bin/python benchmarks/what_phi_sees.py SET_IMAGES --real TRAIN_TARGETS --held-out VALIDATION_TARGETS --phi RUN

Use train chips for --real and held-out (validation or tuning) chips for --held-out.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))


def blur(x: np.ndarray, k: int = 4) -> np.ndarray:
    """(N, S, S) → the same averaged over k × k blocks and upsampled bilinearly."""
    t = torch.from_numpy(x)[:, None]
    return F.interpolate(F.avg_pool2d(t, k), scale_factor=k, mode="bilinear", align_corners=False)[:, 0].numpy()


def with_levels(x: np.ndarray, sources: list[np.ndarray]) -> np.ndarray:
    """Each chip's pixels, ranked, take the sorted gray levels of sources[i] (same size)."""
    out = np.empty_like(x)
    for i, image in enumerate(x):
        order = np.argsort(image.reshape(-1), kind="stable")
        flat = np.empty(image.size, np.float32)
        flat[order] = np.sort(sources[i].reshape(-1))
        out[i] = flat.reshape(image.shape)
    return out


def sensitivity(images: np.ndarray, real: np.ndarray, encoder, replicates: int) -> None:
    from sasmi.eval.features import phi_features
    from sasmi.eval.metrics import fid, fid_mean_part, fid_ratio_matched

    rng = np.random.default_rng(0)
    pooled = np.sort(real.reshape(-1))[np.linspace(0, real.size - 1, real[0].size).astype(int)].reshape(real[0].shape)
    real_phi = phi_features(encoder, real)
    views = {"as they are": images, "blurred over 4 px": blur(images),
             "pooled real histogram on every chip": with_levels(images, [pooled] * len(images)),
             "a random real chip's histogram each": with_levels(images, [real[i] for i in rng.integers(len(real), size=len(images))]),
             "real chips blurred over 4 px (vs themselves)": blur(real)}
    print(f"φ-FID ratio to {len(real)} real chips ({replicates} replicates)")
    for name, x in views.items():
        f = phi_features(encoder, np.clip(x, 0.0, 1.0))
        r = fid_ratio_matched(f, real_phi, replicates, 0)
        print(f"  {name:46s} {r.value:.3f} ± {r.std:.2f}   from the means {100 * fid_mean_part(f, real_phi) / fid(f, real_phi):3.0f} %",
              flush=True)


def separability(images: np.ndarray, real: np.ndarray, held_out: np.ndarray, steps: int) -> None:
    from sklearn.metrics import roc_auc_score

    from sasmi.gan.critic import Critic, CriticConfig

    def standardise(x):
        return (x - x.mean((2, 3), keepdim=True)) / x.std((2, 3), keepdim=True).clamp_min(1e-6)

    def gray_levels(x):  # sorted levels only, laid out as an image for the same critic
        s = x.shape[-1]
        return x.flatten(1).sort(dim=1).values.view(-1, 1, s, s)

    def tensor_blur(x):
        return torch.from_numpy(blur(x[:, 0].numpy()))[:, None]

    as_tensor = lambda x: torch.from_numpy(x)[:, None] * 2 - 1  # (N, 1, S, S) in [-1, 1]
    train_set, test_set = as_tensor(images[:300]), as_tensor(images[300:])
    real_t, held_t = as_tensor(real), as_tensor(held_out)
    views = {"raw": lambda x: x, "blurred over 4 px": tensor_blur, "speckle (raw − blurred)": lambda x: x - tensor_blur(x),
             "each chip standardised": standardise, "sorted gray levels only": gray_levels}
    print(f"AUC of a critic telling real from the set ({steps} steps; held out: {len(held_t)} real, {len(test_set)} of the set)")
    g = torch.Generator().manual_seed(0)
    for name, view in views.items():
        torch.manual_seed(0)
        critic = Critic(CriticConfig(16), real.shape[-1])
        opt = torch.optim.Adam(critic.parameters(), 2e-4, betas=(0.5, 0.9))
        for _ in range(steps):
            r = real_t[torch.randint(len(real_t), (16,), generator=g)]
            f = train_set[torch.randint(len(train_set), (16,), generator=g)]
            s = critic(view(torch.cat([r, f])))
            loss = F.softplus(-s[:16]).mean() + F.softplus(s[16:]).mean()
            opt.zero_grad()
            loss.backward()
            opt.step()
        with torch.no_grad():
            sr, sf = critic(view(held_t)).numpy(), critic(view(test_set)).numpy()
        auc = roc_auc_score(np.r_[np.ones(len(sr)), np.zeros(len(sf))], np.r_[sr, sf])
        print(f"  {name:28s} {auc:.3f}", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("images", help="folder of the set's chips (e.g. RUN/renders/images)")
    parser.add_argument("--real", required=True, help="real chips (train)")
    parser.add_argument("--held-out", required=True, help="real chips the critic does not learn from")
    parser.add_argument("--phi", required=True, help="autoencoder run")
    parser.add_argument("--replicates", type=int, default=30)
    parser.add_argument("--steps", type=int, default=400)
    args = parser.parse_args()

    from sasmi.eval.features import as_encoder, load_images

    def read(folder):
        return load_images(sorted(Path(folder).glob("*.png")), 128)

    images, real, held_out = read(args.images), read(args.real), read(args.held_out)
    if len(images) <= 300:
        sys.exit(f"{args.images}: needs more than 300 chips (300 train the critic, the rest test it)")
    sensitivity(images, real, as_encoder(args.phi), args.replicates)
    separability(images, real, held_out, args.steps)


if __name__ == "__main__":
    main()
