"""sasmi installs as a package: used from another folder, the GAN code is sasmi.gan, presets, recipes and the
reference weights ship."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_installed_package_works_outside_the_checkout(tmp_path):
    target = tmp_path / "site"
    subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--no-build-isolation",
                    "--target", str(target), str(REPO)], check=True, capture_output=True, timeout=300)
    assert not (target / "gan").exists()  # no global `gan` package
    script = """
import importlib.util, sasmi
from sasmi import load_preset
from sasmi.atr.datasets import RenderSet, RealChips
from sasmi.eval import phi_fid
from sasmi.gan.loop import train
from sasmi.gan.recipes import load_recipe
from sasmi.gan.generator import load_generator
from sasmi.weights import shipped
assert load_generator(shipped("sasgan")).image_size == 128 and str(shipped("phi")).startswith(TARGET)
assert sasmi.__file__.startswith(TARGET), sasmi.__file__
assert importlib.util.find_spec("gan") is None
print(load_preset("cylinder_chip").path.parent.name, sorted(load_recipe("baseline")))
"""
    env = {"PYTHONPATH": str(target), "PATH": "/usr/bin:/bin"}
    out = subprocess.run([sys.executable, "-c", f"TARGET = {str(target)!r}\n" + script], cwd=tmp_path, env=env,
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split()[0] == "presets"  # the installed copy of scenes/, not the checkout's
    version = subprocess.run([sys.executable, "-m", "sasmi", "--version"], cwd=tmp_path, env=env,
                             capture_output=True, text=True, timeout=120)
    assert version.stdout.startswith("sasmi ")
