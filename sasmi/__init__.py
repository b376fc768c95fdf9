"""sasmi: artificial synthetic-aperture-sonar images with full control over the scene.

    from sasmi import load_preset, render
    out = render(load_preset("scenes/cylinder_chip.toml").sample(seed=0, index=0))
    out.image, out.mask, out.labels
"""
__version__ = "0.1.0"

from sasmi.scene.preset import load_preset  # noqa: E402  (no renderer import: cheap)
from sasmi.scene.model import Scene  # noqa: E402
# The package sasmi.render is callable: render(scene, size, spp). It imports Mitsuba on first use.
from sasmi import render  # noqa: E402

__all__ = ["Scene", "load_preset", "render", "__version__"]
