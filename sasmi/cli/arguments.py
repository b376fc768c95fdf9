"""argparse types that check numbers and paths at the door, from the ranges in sasmi/limits.py.

    p.add_argument("--spp", type=int, default=16)   # apply_limits gives it limits.FLAGS["--spp"]

A bad value makes argparse exit 2 with one line: `sasmi CMD: error: argument --spp: ...`.
`apply_limits(parser)` gives every flag named in limits.FLAGS its range even where the
command declared a plain int/float, and checks folder inputs and output parents, so a
command cannot forget a check.
"""
from __future__ import annotations

import argparse
import os
from pathlib import Path
from typing import Any, Callable

from sasmi import limits
from sasmi.limits import Range

INPUT_FOLDERS = ("--real", "--renders", "--in")  # always existing folders (run folders: their loaders check)
OUTPUTS = ("--out",)  # a file or folder to create: its nearest existing parent must be a writable folder


def _parse_int(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None


def _parse_float(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None


def ranged(r: Range) -> Callable[[str], Any]:
    """argparse type: parse as r.kind, then check the range (nan and inf are never allowed)."""
    parse = _parse_int if r.kind is int else _parse_float

    def convert(text: str):
        value = parse(text)
        problem = r.problem(value)
        if problem:
            raise argparse.ArgumentTypeError(f"{problem} (allowed: {r.allowed()})")
        return value

    convert.__name__ = "int" if r.kind is int else "float"  # argparse names the type in some messages
    convert.range = r  # which range a flag was given (tests check that it is limits.FLAGS')
    return convert


def flag(name: str) -> Callable[[str], Any]:
    """The argparse type of a flag listed in limits.FLAGS, e.g. flag("--seed")."""
    return ranged(limits.FLAGS[name])


def flag_or_all(name: str) -> Callable[[str], Any]:
    """The type of a flag listed in limits.FLAGS that also takes the word "all" (-> None)."""
    number = flag(name)

    def convert(text: str):
        return None if text == "all" else number(text)

    convert.__name__, convert.range = number.__name__, number.range
    return convert


def existing_folder(text: str) -> Path:
    path = Path(text)
    if not path.exists():
        raise argparse.ArgumentTypeError(f"{text}: not a folder (it does not exist)")
    if not path.is_dir():
        raise argparse.ArgumentTypeError(f"{text}: not a folder")
    return path


def creatable(text: str) -> Path:
    """A path whose nearest existing ancestor is a folder we may write in."""
    path = Path(text)
    if not text:
        raise argparse.ArgumentTypeError("an empty path")
    parent = path.absolute().parent
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir():
        raise argparse.ArgumentTypeError(f"{text}: cannot be created, {parent} is a file, not a folder")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise argparse.ArgumentTypeError(f"{text}: cannot be created, {parent} is not writable")
    return path


def _then(check: Callable[[str], Any], original: Callable[[str], Any] | None) -> Callable[[str], Any]:
    """Run `check` on the text, then the command's own type, so the value keeps the type it expects."""
    def convert(text: str):
        check(text)
        return (original or str)(text)

    convert.__name__ = getattr(original, "__name__", "str")
    return convert


def _parsers(parser: argparse.ArgumentParser):
    yield parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in set(action.choices.values()):
                yield from _parsers(sub)


def apply_limits(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Give every flag in limits.FLAGS its range, folder inputs an existence check, --out a parent check."""
    for p in _parsers(parser):
        for action in p._actions:
            names = set(action.option_strings)
            for name in names & set(limits.FLAGS):
                if getattr(action.type, "range", None) is limits.FLAGS[name]:
                    continue  # already the table's range (flag_or_all)
                if action.type not in (None, int, float):
                    raise TypeError(f"{name}: declare it with type=int or float; its range is limits.FLAGS[{name!r}]")
                action.type = flag(name)
            if names & set(INPUT_FOLDERS) and action.type in (None, str, Path):
                action.type = _then(existing_folder, action.type)
            if names & set(OUTPUTS) and action.type in (None, str, Path):
                action.type = _then(creatable, action.type)
    return parser
