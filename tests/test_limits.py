"""One source for every range: the flags, the run configs they fill and the recipes read sasmi.limits."""
from __future__ import annotations

import argparse
import ast
from dataclasses import replace

import pytest

from conftest import REPO
from sasmi.cli.main import _subparsers, build_parser
from sasmi.cli.train import TRAINING_FLAGS
from sasmi.errors import SasmiError
from sasmi.limits import FLAGS, SETTINGS


def test_every_flag_of_the_table_takes_its_range_from_it():
    wrong = []
    for parser in _subparsers(build_parser()):
        for action in parser._actions:
            for name in set(action.option_strings) & set(FLAGS):
                if getattr(action.type, "range", None) is not FLAGS[name]:
                    wrong.append(f"{parser.prog} {name}")
    assert not wrong, wrong


def _outside(r):
    """A value just outside a range: above its top, or below its bottom."""
    if r.hi is not None:
        return r.hi + r.multiple if r.kind is int else r.hi * 1.5 + 1e-3
    return r.lo - 1


@pytest.mark.parametrize("dest", [d for d in TRAINING_FLAGS if f"--{d.replace('_', '-')}" in FLAGS])
def test_run_configs_refuse_what_their_flag_refuses_with_the_same_words(dest):
    from sasmi.gan.kinds.sasgan import SasganRun

    name = f"--{dest.replace('_', '-')}"
    bad = _outside(FLAGS[name])
    value = (0.9, bad) if dest == "betas" else bad
    with pytest.raises(SasmiError) as refused:
        replace(SasganRun(), **{dest: value}).validate()
    assert name in str(refused.value) and FLAGS[name].why in str(refused.value)
    with pytest.raises(argparse.ArgumentTypeError):
        FLAGS[name] and _subparser_type(name)(str(bad))


def _subparser_type(name):
    for parser in _subparsers(build_parser()):
        for action in parser._actions:
            if name in action.option_strings:
                return action.type
    raise AssertionError(f"no command has {name}")


@pytest.mark.parametrize("key", sorted(SETTINGS))
def test_recipe_keys_without_a_flag_are_checked_by_the_table(key):
    from sasmi.gan.kinds.dcgan import DcganRun
    from sasmi.gan.kinds.sasgan import SasganRun

    cfg = DcganRun() if key == "final_samples" else SasganRun()
    section, _, field = key.rpartition(".")
    bad = _outside(SETTINGS[key])
    cfg = replace(cfg, **({section: replace(getattr(cfg, section), **{field: bad})} if section else {field: bad}))
    with pytest.raises(SasmiError, match=SETTINGS[key].why.split(";")[0][:20]):
        cfg.validate()


def test_no_range_is_declared_outside_the_table():
    """A Range(...) anywhere but sasmi/limits.py is a second source of truth."""
    found = []
    for root in (REPO / "sasmi", REPO / "gan"):
        for path in root.rglob("*.py"):
            if path.name == "limits.py":
                continue
            for node in ast.walk(ast.parse(path.read_text())):
                if isinstance(node, ast.Call) and getattr(node.func, "id", getattr(node.func, "attr", "")) == "Range":
                    found.append(f"{path.relative_to(REPO)}:{node.lineno}")
    assert not found, found


def test_the_docs_carry_the_table_as_the_code_states_it():
    from sasmi.limits import markdown_table

    assert markdown_table() in (REPO / "docs" / "errors.md").read_text(), \
        "docs/errors.md: paste sasmi.limits.markdown_table() over its table"
