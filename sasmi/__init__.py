"""sasmi: artificial synthetic-aperture-sonar images with full control over the scene.

    from sasmi import load_preset, render
    out = render(load_preset("scenes/cylinder_chip.toml").sample(seed=0, index=0))
    out.image, out.mask, out.labels
"""
__version__ = "0.1.0"

from sasmi.scene import Scene, load_preset  # noqa: E402  (no renderer import: cheap)


def render(scene: Scene, size: int = 256, spp: int = 16):
    """Image (H, W) in [0, 1], mask (0 seafloor, 1 target, 2 shadow) and labels of one scene."""
    from sasmi.mitsuba_render import render as mitsuba_render

    return mitsuba_render(scene, size=size, spp=spp)


__all__ = ["Scene", "load_preset", "render", "__version__"]
