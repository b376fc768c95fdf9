"""The one module that owns POV-Ray: Scene -> SDL text, run `povray`, read its image.

It renders the same `Geometry` as `sasmi.render.mitsuba` (the paper's front end was POV-Ray),
so the cross-check compares like with like:

- the heightfield and every target as `mesh2` with the very same vertices and
  triangles (float32 values written exactly); no normals, so both shade flat facets;
- each emitter as a `spotlight` at the same position, pointed at the same aim point,
  `radius` = Mitsuba's beam_width and `falloff` = its cutoff angle, `tightness 0`;
- inverse-square falloff: a POV-Ray light does not fade unless told to; with
  `fade_power 2` it is multiplied by 2 / (1 + (d / fade_distance)^2), which for a tiny
  fade_distance D is 2 D^2 / d^2 to a relative error (D / d)^2 (< 1e-6 for any seafloor
  point 0.1 chip units from an emitter), so the light colour carries 1 / (2 D^2);
- Lambertian finish: POV-Ray's `diffuse` has no 1/pi, so the light colour carries it;
  `brilliance 2` (diffuse ~ cos^2 of incidence) for a floor with Lambert's cos^2 law;
  no ambient, no specular, `assumed_gamma 1` and `File_Gamma=1.0` keep it linear;
- an orthographic camera straight down over the chip, its `right`/`up` vectors given
  explicitly (with `look_at` POV-Ray ignores the sign of `right` and mirrors the image).

What differs, by design of the two renderers: POV-Ray's spot edge is a cubic in
cos(angle) between `radius` and `falloff`, Mitsuba's is linear in the angle (both are 1
inside the beam width and 0 beyond the cutoff); POV-Ray lights both sides of a triangle,
Mitsuba's diffuse BSDF only the front (the same for closed meshes seen from outside);
POV-Ray traces every light per sample, so its time grows with the emitter count.

The image: a 16-bit grayscale PGM (PIL reads POV-Ray's 16-bit PNGs as 8-bit), gray level
= radiance x `Exposure`, declared on the command line so that nothing clips (see
`radiance_bound`). Opened as it is, the .pov renders with Exposure 1: the gray levels of
sasmi's Mitsuba render before speckle and noise, clipped to [0, 1].
"""
from __future__ import annotations

import math
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

from sasmi.errors import SasmiError
from sasmi.render.geometry import Geometry, TriangleMesh, build_geometry
from sasmi.scene.model import Scene

POVRAY = "povray"
INSTALL_HINT = "POV-Ray not found on PATH: install it with `sudo apt-get install povray` (`make setup` does this)"
CAMERA_HEIGHT = 50.0  # chip units; orthographic, so any height above the tallest target gives the same image
FADE_DISTANCE = 1e-4  # chip units; 2 D^2 / (D^2 + d^2) is 2 D^2 / d^2 to 1e-6 wherever d > 0.1
# 3 x 3 jittered sub-pixel rays plus the centre ray in every pixel (threshold 0): close to
# Mitsuba's box filter, which matters on the heightfield, where a pixel-centre ray falls on
# the diagonal shared by the two triangles of its cell.
ANTIALIAS = ("+A0.0", "+AM1", "+R3", "+J")
IMAGE_OPTIONS = ("+FP16", "Grayscale_Output=true", "File_Gamma=1.0", "-D", "-V")  # linear 16-bit PGM, no display


def scene_sdl(scene: Scene, size: int, title: str = "") -> str:
    """SDL text of `scene` as Mitsuba renders it at `size` x `size` pixels."""
    return geometry_sdl(build_geometry(scene, size), title)


def _vector(v) -> str:
    return "<" + ",".join(f"{float(c):.9g}" for c in v) + ">"


def _mesh2(mesh: TriangleMesh, texture: str) -> str:
    vertices = ",\n".join(_vector(v) for v in mesh.vertices)
    faces = ",\n".join(f"<{a},{b},{c}>" for a, b, c in mesh.faces)
    return (f"mesh2 {{\n  vertex_vectors {{ {len(mesh.vertices)},\n{vertices}\n  }}\n"
            f"  face_indices {{ {len(mesh.faces)},\n{faces}\n  }}\n  {texture}\n}}\n")


def geometry_sdl(g: Geometry, title: str = "") -> str:
    """SDL text of `g`: see the module docstring for how each part matches Mitsuba."""
    # radiance = albedo / pi * I * cos / d^2; POV-Ray: diffuse * pigment * colour * 2 D^2 / d^2 * cos
    colour = g.emitter_intensity / (math.pi * 2 * FADE_DISTANCE**2)
    lines = [
        f"// {title}" if title else "// sasmi scene",
        f"// Render: povray +I<this file> +W{g.size} +H{g.size} {' '.join(IMAGE_OPTIONS)} {' '.join(ANTIALIAS)}",
        "// Declare=Exposure=k scales the gray levels; Declare=Target_Mask=1 renders targets white on black.",
        "#version 3.7;",
        "#ifndef (Exposure) #declare Exposure = 1; #end",
        "#ifndef (Target_Mask) #declare Target_Mask = 0; #end",
        "global_settings { assumed_gamma 1.0 ambient_light 0 }",
        # image right = +x (range), image up = -y, so rows run along +y as in Mitsuba
        f"camera {{ orthographic location <0,0,{CAMERA_HEIGHT}> direction <0,0,-1> right <2,0,0> up <0,-2,0> }}",
        f"#declare Fade_Distance = {FADE_DISTANCE};",
        f"#declare Light_Colour = {colour:.9g} * Exposure;  // I / (pi * 2 Fade_Distance^2)",
        "#macro Emitter(Position, Aim)",
        "  light_source { Position rgb Light_Colour spotlight point_at Aim",
        f"    radius {g.beam_width:.9g} falloff {g.cone_angle:.9g} tightness 0",
        "    fade_distance Fade_Distance fade_power 2 }",
        "#end",
        "#macro Lambertian(Albedo, Mask_Level, Brilliance)",
        "  #if (Target_Mask) texture { pigment { rgb Mask_Level } finish { ambient 0 diffuse 0 emission 1 } }",
        "  #else texture { pigment { rgb Albedo } finish { ambient 0 diffuse 1 brilliance Brilliance emission 0 "
        "specular 0 phong 0 } }",
        "  #end",
        "#end",
        "#if (!Target_Mask)",
        *(f"  Emitter({_vector(p)}, {_vector(a)})" for p, a in zip(g.emitter_positions, g.aims)),
        "#end",
        _mesh2(g.floor, f"Lambertian({g.floor.albedo:.9g}, 0, {g.floor.cos_power})"),
        *(_mesh2(t, f"Lambertian({t.albedo:.9g}, 1, {t.cos_power})") for t in g.targets),
    ]
    return "\n".join(lines)


def radiance_bound(g: Geometry) -> float:
    """About the brightest any pixel can be: the most irradiated vertex, facing every emitter."""
    vertices = np.concatenate([g.floor.vertices, *(t.vertices for t in g.targets)]).astype(np.float64)
    irradiance = sum(1.0 / ((vertices - p) ** 2).sum(1) for p in g.emitter_positions)  # (V,) per unit intensity
    albedo = max([g.floor.albedo, *(t.albedo for t in g.targets)])
    return float(albedo / math.pi * g.emitter_intensity * irradiance.max())


def radiance(sdl: str, size: int, exposure: float) -> tuple[np.ndarray, float]:
    """(H, W) float64 radiance of `sdl` and the seconds POV-Ray took.

    `exposure` scales the gray levels into POV-Ray's 16 bits and is divided out again; it
    must keep every pixel below 1, since POV-Ray clips.
    """
    image, seconds = run(sdl, size, [f"Declare=Exposure={exposure:.9g}", *ANTIALIAS])
    if image.max() >= 1.0:
        raise SasmiError(f"POV-Ray image clipped at exposure {exposure:.3g}: lower it")
    return image / exposure, seconds


def target_mask(sdl: str, size: int) -> np.ndarray:
    """(H, W) bool: a target is the surface seen through the pixel centre (no lights traced)."""
    image, _ = run(sdl, size, ["Declare=Target_Mask=1"])
    return image > 0.5


def run(sdl: str, size: int, options: list[str]) -> tuple[np.ndarray, float]:
    """Render `sdl` with `povray` (argument list, no shell, no display); (H, W) in [0, 1] and seconds."""
    binary = _binary()
    # POV-Ray's default I/O policy lets it write only below its working directory.
    with tempfile.TemporaryDirectory(prefix="sasmi-povray-") as work:
        Path(work, "scene.pov").write_text(sdl)
        args = [binary, "+Iscene.pov", "+Oimage.ppm", f"+W{size}", f"+H{size}", *IMAGE_OPTIONS, *options]
        start = time.perf_counter()
        done = subprocess.run(args, cwd=work, capture_output=True, text=True, stdin=subprocess.DEVNULL)
        seconds = time.perf_counter() - start
        if done.returncode != 0:
            raise SasmiError(f"povray exited with {done.returncode}: {_error_lines(done.stderr)}")
        return read_pgm(Path(work, "image.ppm")), seconds  # P5 data; POV-Ray insists on the .ppm suffix


def _binary() -> str:
    binary = shutil.which(POVRAY)
    if binary is None:
        raise SasmiError(INSTALL_HINT)
    return binary


def _error_lines(stderr: str) -> str:
    """POV-Ray's diagnosis in one line: from its first error line on (it wraps at 80 columns)."""
    lines = [line.strip() for line in stderr.splitlines() if line.strip()]
    first = next((i for i, line in enumerate(lines) if "error" in line.lower()), max(len(lines) - 3, 0))
    return " ".join(lines[first:]) or "no message on stderr"


def read_pgm(path: Path) -> np.ndarray:
    """Binary PGM (P5), 8 or 16 bit, comment lines allowed, as (H, W) float64 in [0, 1]."""
    data = path.read_bytes()
    fields, pos = [], 0
    while len(fields) < 4:
        while data[pos:pos + 1].isspace():
            pos += 1
        if data[pos:pos + 1] == b"#":
            pos = data.index(b"\n", pos)
            continue
        end = pos
        while end < len(data) and not data[end:end + 1].isspace():
            end += 1
        fields.append(data[pos:end])
        pos = end
    if fields[0] != b"P5":
        raise SasmiError(f"{path}: expected a binary PGM (P5), got {fields[0]!r}")
    width, height, maxval = (int(f) for f in fields[1:])
    dtype = ">u2" if maxval > 255 else "u1"
    pixels = np.frombuffer(data, dtype=dtype, count=width * height, offset=pos + 1)
    return pixels.reshape(height, width).astype(np.float64) / maxval


def version() -> str:
    """First line of `povray --version`, e.g. 'POV-Ray 3.7.0.10.unofficial'."""
    done = subprocess.run([_binary(), "--version"], capture_output=True, text=True, stdin=subprocess.DEVNULL)
    return next((line.strip() for line in (done.stdout + done.stderr).splitlines() if line.startswith("POV-Ray")),
                "POV-Ray (unknown version)")
