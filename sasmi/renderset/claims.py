"""Claim files: any number of processes, on any number of hosts, share one output folder.

Before rendering item NAME (a chip index, a tar shard) a process creates CLAIMS/NAME.claim
by a hard link from its own draft, which exactly one process can win on a local or NFSv3+
filesystem (as O_CREAT|O_EXCL), and which never shows the claim empty.
The file records who holds it: host, pid and the pid's start time (so a recycled pid is
not mistaken for the holder). The holder removes it when the item is complete.

A claim of a dead holder is stale and may be taken over:
- same host: the pid no longer runs (or runs a different process);
- other host: its liveness cannot be asked, so the file's age decides (`stale_after`
  seconds without a touch; `kept_alive` touches every held claim meanwhile).
Taking over renames the stale file away first; the rename succeeds for one process only,
and a process that finds it moved a live claim by mistake (a three-way race) puts it back.
"""
from __future__ import annotations

import contextlib
import json
import os
import socket
import threading
import time
from pathlib import Path

HOST = socket.gethostname()
EMPTY_GRACE_S = 60.0  # a claim is written right after its creation; empty for longer means its writer died


def _start_time(pid: int) -> str | None:
    """The pid's start time in clock ticks since boot (Linux), or None where /proc is not there."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    return stat.rsplit(")", 1)[1].split()[19]  # field 22 of stat; the name in parentheses may hold spaces


def _alive(pid: int, started: str | None) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's process: it runs
        pass
    return started is None or _start_time(pid) in (None, started)


class Claims:
    """The claims this process holds in `folder`."""

    def __init__(self, folder: Path, stale_after: float = 3600.0):
        self.folder = Path(folder)
        self.stale_after = stale_after
        self.held: set[str] = set()
        self._me = json.dumps({"host": HOST, "pid": os.getpid(), "started": _start_time(os.getpid())})

    def _path(self, name: str) -> Path:
        return self.folder / f"{name}.claim"

    def take(self, name: str) -> bool:
        """True if this process now holds `name` (it did not, and nobody live does)."""
        if name in self.held:
            return True
        path = self._path(name)
        self.folder.mkdir(parents=True, exist_ok=True)
        # the claim appears whole, by a hard link as exclusive as O_EXCL: a holder killed between
        # creating it and writing it would leave an empty claim that blocks the chip for a minute
        draft = path.with_name(f".{path.name}.{HOST}.{os.getpid()}.{threading.get_ident()}.new")
        draft.write_text(self._me)
        try:
            for _ in range(2):  # once, and once more after taking over a stale claim
                try:
                    os.link(draft, path)
                except FileExistsError:
                    if not self._take_over(path):
                        return False
                    continue
                self.held.add(name)
                return True
            return False
        finally:
            draft.unlink()

    def _is_stale(self, path: Path) -> tuple[bool, str]:
        try:
            text = path.read_text()
            age = time.time() - path.stat().st_mtime
        except FileNotFoundError:
            return True, ""
        try:
            owner = json.loads(text)
        except json.JSONDecodeError:
            return age > EMPTY_GRACE_S, text
        if owner.get("host") == HOST:
            return not _alive(int(owner["pid"]), owner.get("started")), text
        return age > self.stale_after, text

    def _take_over(self, path: Path) -> bool:
        """Remove a stale claim at `path`; True if the caller may try to create it again."""
        stale, text = self._is_stale(path)
        if not stale:
            return False
        aside = path.with_name(f".{path.name}.{HOST}.{os.getpid()}.stale")
        try:
            os.rename(path, aside)
        except FileNotFoundError:
            return True  # someone else removed it; race for the new claim
        if aside.read_text() == text:
            aside.unlink()
            return True
        with contextlib.suppress(FileExistsError):  # we moved a live claim made since we looked: put it back
            os.link(aside, path)
        aside.unlink()
        return False

    def touch(self, name: str) -> None:
        """Tell other hosts that the claim is alive (for items that take longer than `stale_after`)."""
        with contextlib.suppress(FileNotFoundError):
            os.utime(self._path(name))

    @contextlib.contextmanager
    def kept_alive(self, every: float | None = None):
        """Context: a thread touches the held claims every `every` s (default stale_after / 4), so that
        processes on other hosts do not take them over while long items (a tar shard) render."""
        stop = threading.Event()

        def beat() -> None:
            while not stop.wait(every or self.stale_after / 4):
                for name in list(self.held):
                    self.touch(name)

        thread = threading.Thread(target=beat, name="claims-keep-alive", daemon=True)
        thread.start()
        try:
            yield self
        finally:
            stop.set()
            thread.join()

    def release(self, name: str) -> None:
        if name in self.held:
            self.held.discard(name)
            with contextlib.suppress(FileNotFoundError):
                self._path(name).unlink()

    def release_all(self) -> None:
        for name in list(self.held):
            self.release(name)

    def remove_folder(self) -> None:
        """Drop the claims folder once it is empty (the set is complete)."""
        with contextlib.suppress(OSError):
            self.folder.rmdir()
