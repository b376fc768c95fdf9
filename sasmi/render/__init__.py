"""Scene -> chip image, class mask and label. The modules, in pipeline order:

    seafloor.py        height arrays (m) of the seabed: rough surface, ripples, rocks
    geometry.py        Scene -> renderer-neutral triangles, emitters, exposure (chip units)
    llvm.py            find libLLVM, import Mitsuba with sasmi's variant, versions(), numpy -> Dr.Jit
    mitsuba.py         Geometry -> Mitsuba scene -> radiance; Renderer, render(), Rendered
    visibility.py      ray casts: which target each pixel sees, which target shadows it
    post.py            the sonar's gain, speckle and noise: radiance -> gray levels in [0, 1]
    annotate.py        class mask and typed label (sasmi.labels.ChipLabel) from the ray casts
    differentiable.py  θ -> image through Dr.Jit's AD, for `sasmi fit-scene`
    povray.py          the same Geometry through POV-Ray
    crosscheck.py      Mitsuba against POV-Ray on one scene

Importing this package is cheap: the names below are loaded from their modules on first
use, so `import sasmi` does not import Mitsuba. The package is also callable:
`sasmi.render(scene)` is `render(scene)`. A plain function `sasmi.render` would be
replaced by this package as soon as it is imported (or break `import sasmi.render.x as y`).
"""
from __future__ import annotations

import importlib
import sys
import types

_EXPORTS = {
    "Renderer": "mitsuba", "Rendered": "mitsuba", "renderer_for": "mitsuba",
    "versions": "llvm", "VARIANT": "llvm",
    "MASK_SEAFLOOR": "annotate", "MASK_TARGET": "annotate", "MASK_SHADOW": "annotate",
    "DifferentiableRenderer": "differentiable", "BoundScene": "differentiable",
    "PARAMETERS": "differentiable", "scene_parameters": "differentiable",
}


def render(scene, size: int = 256, spp: int = 16):
    """Image (H, W) in [0, 1], mask (0 seafloor, 1 target, 2 shadow) and label of one scene."""
    from sasmi.render.mitsuba import render as mitsuba_render

    return mitsuba_render(scene, size=size, spp=spp)


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(importlib.import_module(f"sasmi.render.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module 'sasmi.render' has no attribute {name!r}")


class _CallablePackage(types.ModuleType):
    def __call__(self, scene, size: int = 256, spp: int = 16):
        return render(scene, size=size, spp=spp)


sys.modules[__name__].__class__ = _CallablePackage
__all__ = ["render", *_EXPORTS]
