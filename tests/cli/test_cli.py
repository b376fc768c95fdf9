"""The command line as a whole: --version, and every default shown in --help."""
from __future__ import annotations

import argparse

import pytest

from sasmi import __version__
from sasmi.cli.main import _subparsers, build_parser, main


def test_version(capsys):
    assert main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"sasmi {__version__}"


def test_every_help_names_every_default():
    missing = []
    for parser in _subparsers(build_parser()):
        for action in parser._actions:
            # by identity: a default of 0 equals False and must still be shown
            no_default = any(action.default is nothing for nothing in (None, False, argparse.SUPPRESS)) \
                or action.default == ""
            if action.option_strings and not no_default and action.help is not argparse.SUPPRESS:
                text = parser._get_formatter()._expand_help(action) if action.help else ""  # no help: no default either
                if "default" not in text:
                    missing.append(f"{parser.prog} {action.option_strings[0]}")
    assert not missing, missing


@pytest.mark.parametrize("command", ["render", "split", "stats", "train", "translate", "generate", "fit", "evaluate",
                                     "crosscheck", "fit-scene", "export", "atr-bench", "sheet"])
def test_every_command_has_help(command, capsys):
    with pytest.raises(SystemExit) as exit_:
        build_parser().parse_args([command, "--help"])
    assert exit_.value.code == 0 and "usage: sasmi" in capsys.readouterr().out
