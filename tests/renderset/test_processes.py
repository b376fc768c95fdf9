"""Local processes that each make a share of a render set: one progress count, and a failed share stops the rest."""
from __future__ import annotations

import sys
import time
from functools import partial
from pathlib import Path

import pytest

from sasmi.errors import SasmiError
from sasmi.renderset.processes import complete_chips, run_shares


def write_share(out: Path, count: int, share: int, shares: int) -> None:
    (out / "labels").mkdir(parents=True, exist_ok=True)
    for i in range(share, count, shares):
        (out / "labels" / f"{i:06d}.json").write_text("{}")


def fail_second(out: Path, share: int, shares: int) -> None:
    if share == 1:
        print("share 2: a clear error", file=sys.stderr)
        sys.exit(2)
    time.sleep(120)  # stopped by run_shares long before
    (out / "finished").write_text("")


def test_every_share_runs_in_its_own_process(tmp_path):
    run_shares(partial(write_share, tmp_path, 7), 3, partial(complete_chips, tmp_path), 7, "test", progress=False)
    assert complete_chips(tmp_path) == 7 and complete_chips(tmp_path, (1, 3)) == 2  # chips 1 and 4
    assert sorted(p.name for p in (tmp_path / "labels").iterdir()) == [f"{i:06d}.json" for i in range(7)]


def test_a_failed_share_stops_the_others_and_is_named(tmp_path):
    start = time.monotonic()
    with pytest.raises(SasmiError, match=r"test 2/2 stopped with exit code 2 .*rerun the same command"):
        run_shares(partial(fail_second, tmp_path), 2, lambda: 0, 4, "test", progress=False)
    assert time.monotonic() - start < 60  # the sleeping share was stopped, not waited for
    assert not (tmp_path / "finished").exists()


def test_a_share_reports_what_the_user_can_fix_in_one_line(capsys):
    import errno

    from sasmi.renderset.processes import in_share

    def full_disk():
        raise OSError(errno.ENOSPC, "No space left on device", "/out/images/000003.png")

    with pytest.raises(SystemExit) as stopped:
        in_share("render", 1, full_disk)
    assert stopped.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("sasmi render: error: ") and "000003.png" in err[0]
    with pytest.raises(ZeroDivisionError):  # a bug keeps its traceback
        in_share("render", 1, lambda: 1 / 0)
