"""What counts as bad user input, and the one line the CLI prints for it (exit code 2).

SasmiError is raised by sasmi's own checks. `user_error_message` also recognises the
failures that user input causes deep inside libraries: OSError (no space, no permission,
a file where a folder belongs), a checkpoint that torch cannot load or that does not fit
its network, and running out of memory. Anything else is a bug in sasmi (exit code 1).
"""
from __future__ import annotations

import os
import traceback
from types import TracebackType


class SasmiError(ValueError):
    """Bad user input: a preset field, a file, a flag. The message names the culprit."""


class Terminated(BaseException):
    """SIGTERM outside a training (whose loop stops at a step instead): raised where the command is, as
    Ctrl-C raises KeyboardInterrupt, so that temporary files are removed and one line said."""


class Stopped(Exception):
    """A long command stopped by a signal at a safe point, its work saved; the message says how to
    continue. The CLI exits 128 + the signal's number, as a shell reports a process the signal ended."""

    def __init__(self, signum: int, message: str):
        super().__init__(message)
        self.code = 128 + signum


def first_line(text: object, limit: int = 300) -> str:
    """The first non-empty line of `text`, shortened: library messages can be pages long."""
    lines = [line.strip() for line in str(text).splitlines() if line.strip()]
    line = lines[0] if lines else ""
    return line if len(line) <= limit else line[:limit - 3] + "..."


def one_line(text: object, limit: int = 1000) -> str:
    """All lines of `text` joined by "; ", shortened: our own messages, which name the culprit."""
    line = "; ".join(line.strip() for line in str(text).splitlines() if line.strip())
    return line if len(line) <= limit else line[:limit - 3] + "..."


def _frames(tb: TracebackType | None):
    """(filename, function, locals) of each frame of a traceback, outermost first."""
    for frame, _ in traceback.walk_tb(tb):
        yield frame.f_code.co_filename.replace(os.sep, "/"), frame.f_code.co_name, frame.f_locals


def _path_local(frames: list, names: tuple[str, ...]) -> str | None:
    """The innermost local called one of `names` holding a path, e.g. torch.load's `f`."""
    for _, _, local in reversed(frames):
        for name in names:
            value = local.get(name)
            if isinstance(value, (str, os.PathLike)):
                return os.fspath(value)
    return None


def oserror_message(e: OSError) -> str:
    name = e.filename if e.filename is not None else ""
    what = e.strerror or first_line(e) or type(e).__name__
    if e.filename2 is not None:
        return f"{name} -> {e.filename2}: {what}"
    return f"{name}: {what}" if name else what


def _checkpoint_problem(e: BaseException) -> str:
    """What torch.load's failure means for the user; its own messages are pages about weights_only."""
    if isinstance(e, EOFError):
        return "empty or cut short"
    if type(e).__name__ == "UnpicklingError":
        return "torch's weights-only loader refused it: not plain tensors, it may carry code"
    if isinstance(e, RuntimeError) and "zip archive" in str(e):
        return "truncated, or not a torch file"
    if isinstance(e, OSError):
        return oserror_message(e)
    return f"{type(e).__name__}: {first_line(e, 160)}"


def user_error_message(e: BaseException) -> str | None:
    """One line naming the file or field if `e` was caused by user input, else None (a bug)."""
    if isinstance(e, SasmiError):
        return one_line(e)
    frames = list(_frames(e.__traceback__))
    in_torch_load = any(f.endswith("torch/serialization.py") and fn == "load" for f, fn, _ in frames)
    if in_torch_load:  # truncated, empty, random bytes, a pickle carrying code, a disk error while reading
        path = _path_local([fr for fr in frames if fr[0].endswith("torch/serialization.py")], ("f",))
        return f"{path or 'checkpoint'}: not a loadable sasmi checkpoint ({_checkpoint_problem(e)})"
    if isinstance(e, OSError):
        return oserror_message(e)
    if isinstance(e, RuntimeError) and any(fn == "load_state_dict" and f.endswith("torch/nn/modules/module.py")
                                           for f, fn, _ in frames):
        path = _path_local(frames, ("path", "run_dir", "checkpoint"))
        return (f"{path or 'checkpoint'}: its weights do not fit the network ({first_line(e, 160)}); "
                "it was made by another kind of run or another version of sasmi")
    if isinstance(e, MemoryError) or type(e).__name__ == "OutOfMemoryError":  # torch.cuda.OutOfMemoryError
        return f"out of memory ({first_line(e, 160) or type(e).__name__}); lower --size, --batch or --count"
    return None
