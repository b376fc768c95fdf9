"""`sasmi` command line: parse, build the dataclasses, call one function per command.

Every user error surfaces as a SasmiError and is printed as one line with exit code 2.
"""
from __future__ import annotations

import argparse
import sys

from sasmi.commands import (atr_cmd, crosscheck_cmd, evaluate_cmd, fit_cmd, generate_cmd, render_cmd, split_cmd,
                            stats_cmd, train_cmd, translate_cmd)
from sasmi.errors import SasmiError

COMMANDS = (render_cmd, train_cmd, translate_cmd, generate_cmd, evaluate_cmd, crosscheck_cmd, fit_cmd, split_cmd,
            stats_cmd, atr_cmd)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="sasmi", description="Artificial SAS images: render, learn realism, evaluate.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for command in COMMANDS:
        command.add_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.run(args) or 0
    except SasmiError as e:
        print(f"sasmi {args.command}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"sasmi {args.command}: interrupted; finished work is kept (render/generate: rerun the same command; "
              "train: add --resume)", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
