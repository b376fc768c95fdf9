"""Mitsuba's CPU backend: find a usable libLLVM, import Mitsuba with the variant sasmi renders with.

Everything that touches Mitsuba or Dr.Jit gets them from `import_mitsuba`, so the LLVM
check and the variant are settled in one place, and the one-line install hint is the
same wherever the library is missing. `aligned` is the one numpy -> Dr.Jit transfer.
"""
from __future__ import annotations

import glob
import os
import re

import numpy as np

from sasmi.errors import SasmiError

VARIANT = "llvm_ad_mono"
LLVM_HINT = ("Mitsuba's CPU backend needs LLVM 19: install it with `apt-get install libllvm19` "
             "(or point DRJIT_LIBLLVM_PATH at a libLLVM.so of version 16 or newer)")
MIN_LLVM = 16  # Debian 12's default 14/15 crash Dr.Jit 1.5 ("Cannot select ... fminimum")


def llvm_version(path: str) -> int | None:
    m = re.search(r"libLLVM(?:-|\.so\.)(\d+)", os.path.basename(path))
    return int(m.group(1)) if m else None


def find_llvm() -> str | None:
    """Newest libLLVM >= MIN_LLVM on the system, or None."""
    found = []
    for path in glob.glob("/usr/lib/*/libLLVM*.so*") + glob.glob("/usr/lib/llvm-*/lib/libLLVM*.so*"):
        version = llvm_version(path)
        if version is not None and version >= MIN_LLVM:
            found.append((version, path))
    return max(found)[1] if found else None


def import_mitsuba():
    """(mitsuba, drjit) with VARIANT set; a SasmiError with the install hint when LLVM is missing or too old."""
    if "DRJIT_LIBLLVM_PATH" not in os.environ:
        path = find_llvm()
        if path is None:
            raise SasmiError(LLVM_HINT)
        os.environ["DRJIT_LIBLLVM_PATH"] = path
    version = llvm_version(os.environ["DRJIT_LIBLLVM_PATH"])
    if version is not None and version < MIN_LLVM:  # would abort the process later, not raise
        raise SasmiError(f"DRJIT_LIBLLVM_PATH points at LLVM {version}; {LLVM_HINT}")
    import drjit as dr
    import mitsuba as mi

    try:
        mi.set_variant(VARIANT)
    except (ImportError, RuntimeError) as e:
        raise SasmiError(f"{LLVM_HINT} ({e})") from None
    return mi, dr


def versions() -> dict:
    """What a run record notes about the renderer."""
    mi, dr = import_mitsuba()
    return {"mitsuba": mi.__version__, "drjit": dr.__version__, "variant": VARIANT,
            "llvm": os.environ.get("DRJIT_LIBLLVM_PATH", "")}


def aligned(a: np.ndarray, dtype=np.float32) -> np.ndarray:
    """A flat copy of `a` on a 64-byte boundary, for handing to Dr.Jit.

    Dr.Jit maps numpy memory without copying and compiles one kernel variant for aligned
    and one for unaligned inputs, so arrays of random alignment would trigger random
    recompiles (seconds each); aligned copies keep every scene on one cached kernel.
    """
    a = np.asarray(a, dtype=dtype).ravel()
    items = 64 // a.itemsize
    buffer = np.empty(a.size + items, dtype=dtype)
    start = (-buffer.ctypes.data % 64) // a.itemsize
    out = buffer[start:start + a.size]
    out[:] = a
    return out
