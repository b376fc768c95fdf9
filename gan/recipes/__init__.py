"""SAS GAN recipes: small commented TOML files of SasganRun settings, read by one function.

`sasmi fit --recipe NAME` and `sasmi train sasgan --recipe NAME` both read a recipe here, so the
stage command trains exactly what the one-command run trains.
"""
from __future__ import annotations

from pathlib import Path

from sasmi.errors import SasmiError

FOLDER = Path(__file__).resolve().parent
DEFAULT = "real_levels"


def shipped() -> list[str]:
    return sorted(p.stem for p in FOLDER.glob("*.toml"))


def recipe_path(recipe: str, flag: str = "--recipe") -> Path:
    """A TOML file, or the name of a shipped recipe."""
    path = Path(recipe)
    if path.is_file():
        return path
    path = FOLDER / f"{recipe}.toml"
    if not path.is_file():
        raise SasmiError(f"{flag} {recipe}: not a TOML file nor a shipped recipe ({', '.join(shipped())})")
    return path


def load_recipe(recipe: str, flag: str = "--recipe") -> dict:
    """The SasganRun fields a recipe sets, as config values; a SasmiError names an unknown or bad key."""
    import tomllib
    from dataclasses import fields, is_dataclass

    from sasmi.gan.kinds.sasgan import SasganRun
    from sasmi.gan.run import config_from_dict

    path = recipe_path(recipe, flag)
    try:
        raw = tomllib.loads(path.read_text())
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as e:
        raise SasmiError(f"{flag} {path}: cannot read ({e})") from None
    defaults = SasganRun()
    for key, value in raw.items():
        if not hasattr(defaults, key):
            raise SasmiError(f"{flag} {path}: {key}: not a SAS GAN setting (see docs/gan.md)")
        nested = getattr(defaults, key)
        if is_dataclass(nested) and (not isinstance(value, dict)
                                     or set(value) - {f.name for f in fields(nested)}):
            raise SasmiError(f"{flag} {path}: [{key}] holds a key that is not a setting of it")
    cfg = config_from_dict(SasganRun, raw, f"{flag} {path}")
    try:
        cfg.validate()
    except SasmiError as e:
        raise SasmiError(f"{flag} {path}: {e}") from None
    return {key: getattr(cfg, key) for key in raw}
