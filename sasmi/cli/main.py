"""`sasmi` command line: parse, build the dataclasses, call one function per command.

Exit codes (docs/errors.md):
  0  done
  1  a check failed (crosscheck) or a bug in sasmi: one line, and SASMI_DEBUG=1 shows the traceback
  2  bad input: one line `sasmi CMD: error: ...` naming the flag, field or file; nothing half-written
  130 interrupted (Ctrl-C); finished work is kept
"""
from __future__ import annotations

import argparse
import os
import signal
import sys
import threading
import warnings

from sasmi.cli.arguments import apply_limits
from sasmi.cli import atr, calibrate, chips, crosscheck, evaluate, fit, fit_scene, generate, render, split, stats, train, translate
from sasmi.errors import Stopped, Terminated, first_line, one_line, user_error_message
from sasmi.limits import check_render_cost

COMMANDS = (render, chips, split, stats, train, translate, generate, fit, evaluate, crosscheck, fit_scene, calibrate, atr)

DEBUG = "SASMI_DEBUG"  # set to 1 to see the traceback of any error


class Parser(argparse.ArgumentParser):
    """argparse with one-line errors: the usage block is in --help, not in every error."""

    def error(self, message: str):
        command = " ".join(self.prog.split()[:2])  # "sasmi train", also for "sasmi train sasgan"
        self.exit(2, f"{command}: error: {first_line(message, 1000)} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    from sasmi import __version__

    parser = Parser(prog="sasmi", description="Artificial SAS images: render, learn realism, evaluate.")
    parser.add_argument("--version", action="version", version=f"sasmi {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for command in COMMANDS:
        command.add_parser(sub)
    return show_defaults(apply_limits(parser))


def _subparsers(parser: argparse.ArgumentParser):
    yield parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for child in action.choices.values():
                yield from _subparsers(child)


def show_defaults(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Every --help names each flag's default, whichever command defined the flag and however."""
    for p in _subparsers(parser):
        for action in p._actions:
            if action.help in (None, argparse.SUPPRESS) or "%(default)" in action.help or "default" in action.help:
                continue
            # by identity: 0 == False, and a --seed's default 0 is worth showing, a switch's False is not
            if any(action.default is nothing for nothing in (None, argparse.SUPPRESS, False)) or action.default == "" \
                    or action.option_strings == []:
                continue
            action.help += " (default: %(default)s)"
    return parser


def check_flag_combinations(args: argparse.Namespace) -> None:
    """Checks that span flags (each flag alone is checked by its argparse type)."""
    size, spp = getattr(args, "size", None), getattr(args, "spp", None)
    if size is not None and spp is not None:
        check_render_cost(size, spp)


def _one_line_warning(message, category, filename, lineno, file=None, line=None) -> None:
    print(f"sasmi: warning: {one_line(message, 300)}", file=sys.stderr if file is None else file)


def main(argv: list[str] | None = None) -> int:
    with warnings.catch_warnings():  # library warnings as one line each, not two with a source line
        warnings.showwarning = _one_line_warning
        # torch.load warns about the pickle protocol of any file it then refuses: noise beside our one line
        warnings.filterwarnings("ignore", message="Detected pickle protocol")
        return _main(argv)


_TERMINATED: list[int] = []  # set by the handler: a library may wrap the exception (Dr.Jit: a RuntimeError)


def _command_ended(prog: str, e: BaseException) -> int:
    what = "terminated (SIGTERM)" if isinstance(e, Terminated) else "interrupted"
    how = "add --resume to continue" if prog == "sasmi train" else "rerun the same command to continue"
    print(f"{prog}: {what}; finished work is kept: {how}", file=sys.stderr)
    return 143 if isinstance(e, Terminated) else 130


def _terminated(signum, frame) -> None:
    _TERMINATED.append(signum)
    raise Terminated()


def _main(argv: list[str] | None) -> int:
    in_main_thread = threading.current_thread() is threading.main_thread()  # Python takes signals there only
    previous = signal.signal(signal.SIGTERM, _terminated) if in_main_thread else None
    _TERMINATED.clear()
    try:
        return _command(argv)
    finally:
        if in_main_thread:
            signal.signal(signal.SIGTERM, previous)


def _command(argv: list[str] | None) -> int:
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as e:  # --help (0) or a bad flag (2, already printed): a code, like every other outcome
        return e.code if isinstance(e.code, int) else 2
    prog = f"sasmi {args.command}"
    try:
        check_flag_combinations(args)
        return args.run(args) or 0
    except Stopped as e:  # a training stopped by SIGTERM or Ctrl-C at a step, its checkpoint written
        print(f"{prog}: {e}", file=sys.stderr)
        return e.code
    except (KeyboardInterrupt, Terminated) as e:
        return _command_ended(prog, e)
    except Exception as e:  # the last line of defence: no traceback for anything the user can fix
        if _TERMINATED:  # a SIGTERM that a library wrapped in its own error
            return _command_ended(prog, Terminated())
        if os.environ.get(DEBUG) == "1":
            raise
        message = user_error_message(e)
        if message is not None:
            print(f"{prog}: error: {message}", file=sys.stderr)
            return 2
        print(f"{prog}: internal error: {type(e).__name__}: {first_line(e, 300)}\n"
              f"This is a bug in sasmi; rerun with {DEBUG}=1 for the traceback and report it.", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
