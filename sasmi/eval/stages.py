"""An evaluation's finished stages kept in OUT/.stages until its report is written, so that one stopped by
SIGTERM, Ctrl-C or kill -9 goes on from the stage it was in when rerun.

Each stage's result is kept as JSON under a key of everything it depends on: the evaluation's settings
and every set's φ and pixels. Another real folder, another φ, a chip rewritten or another flag gives
another key, and the stage is computed afresh. The generated sets' φ are kept there too (sasmi.eval.cache);
the real set's go to the user's φ cache as always.
"""
from __future__ import annotations

import hashlib
import json
import shutil
from dataclasses import asdict
from pathlib import Path
from typing import Callable, Sequence

from sasmi.images import write_text

FOLDER = ".stages"


class Stages:
    """get(name, compute): the stage's JSON-ready result, kept from a stopped run or computed and kept."""

    def __init__(self, out_dir: str | Path | None, key: str = ""):
        self.folder = None if out_dir is None else Path(out_dir) / FOLDER
        self.key = key

    def get(self, name: str, compute: Callable[[], object], log: Callable[[str], None], what: str):
        path = None if self.folder is None else self.folder / f"{name}.json"
        if path is not None and path.is_file():
            try:
                kept = json.loads(path.read_text())
            except (OSError, ValueError):  # a file cut short by a full disk: computed afresh
                kept = None
            if isinstance(kept, dict) and kept.get("key") == self.key:
                log(f"{what}: kept from the stopped run")
                return kept["value"]
        log(what)
        value = compute()
        if path is not None:
            text = json.dumps({"key": self.key, "value": value}, default=_plain)
            write_text(path, text)
            return json.loads(text)["value"]  # as a rerun will read it: one report either way
        return value


def _plain(x):
    """numpy's and pathlib's values as JSON's (NaN stays NaN: Python's json reads it back)."""
    import numpy as np

    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, Path):
        return str(x)
    raise TypeError(f"{type(x).__name__} is not kept by an evaluation stage")


def stages_key(cfg, sets: Sequence) -> str:
    """A hash of the settings and of every FeatureSet's name, folder, φ and pixels (the real set first)."""
    h = hashlib.sha256(json.dumps(asdict(cfg), sort_keys=True, default=str).encode())
    for s in sets:
        h.update(f"{s.name}\t{Path(s.folder).resolve()}\n".encode())
        h.update(s.phi.tobytes())
        h.update(s.images.tobytes())
    return h.hexdigest()


def clear(out_dir: str | Path) -> None:
    """Drop the kept stages once the report they made is written."""
    shutil.rmtree(Path(out_dir) / FOLDER, ignore_errors=True)
