"""The compiled FILM kernel (``film_kernel.c``): built once per source, loaded with ctypes.

The C source is compiled with the system C compiler (``$CC``, default ``cc``; the same one
dolfinx's JIT needs) into ``$CLOTHFEM_CACHE_DIR`` (default ``$XDG_CACHE_HOME/clothfem`` or
``~/.cache/clothfem``), named by a hash of the source and flags, so an edited kernel is
rebuilt and an unchanged one is loaded in milliseconds. Each process builds into a private
temporary file and renames it into place (atomic), so MPI ranks may build concurrently.
No ``-ffast-math`` and no FMA contraction: the kernel's arithmetic is IEEE, as NumPy's.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import shlex
import subprocess
import tempfile
from functools import cache
from pathlib import Path

__all__ = ["KernelBuildError", "film_kernel"]

_SOURCE = Path(__file__).with_name("film_kernel.c")
_FLAGS = ["-O2", "-fPIC", "-shared", "-ffp-contract=off", "-fno-fast-math", "-std=c99"]


class KernelBuildError(RuntimeError):
    """The C compiler could not build the FILM kernel (message names the command)."""


def _cache_dir() -> Path:
    if d := os.environ.get("CLOTHFEM_CACHE_DIR"):
        return Path(d)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "clothfem"


def _build(src: Path) -> Path:
    cc = shlex.split(os.environ.get("CC", "cc"))
    text = src.read_bytes()
    key = hashlib.sha256(text + " ".join(cc + _FLAGS).encode()).hexdigest()[:16]
    out_dir = _cache_dir()
    lib = out_dir / f"{src.stem}_{key}.so"
    if lib.exists():
        return lib
    out_dir.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{src.stem}_", suffix=".so", dir=out_dir)
    os.close(fd)
    cmd = [*cc, *_FLAGS, "-o", tmp, str(src), "-lm"]
    try:
        res = subprocess.run(cmd, capture_output=True, text=True)
    except OSError as e:
        os.unlink(tmp)
        raise KernelBuildError(f"cannot run the C compiler {cc[0]!r} ({e}); set CC") from None
    if res.returncode != 0:
        os.unlink(tmp)
        first = (res.stderr.strip().splitlines() or ["(no output)"])[0]
        raise KernelBuildError(f"building {src.name} failed: {' '.join(cmd)}: {first}")
    os.replace(tmp, lib)
    return lib


_P, _L, _F, _INT = ctypes.c_void_p, ctypes.c_long, ctypes.c_double, ctypes.c_int


@cache
def film_kernel():
    """The ``film_correct`` C function (built on first use; :class:`KernelBuildError` if the
    compiler fails). Its arguments are documented in ``film_kernel.c``."""
    fn = ctypes.CDLL(str(_build(_SOURCE))).film_correct
    fn.restype = ctypes.c_int
    # n, xs, vs, m, dt, K, c, Q, r, vc, om, has_mu, mu, offset, max_passes, tol, max_iter,
    # gap_tol, fixed (uint8 mask or NULL), then the outputs x, v, active, lam_n, force,
    # friction, normal, body, gap, stick, dissipation, unresolved. Arrays are passed as
    # addresses of C-contiguous float64 (int64 body, uint8 flags) arrays: the caller
    # (clothfem.contact.explicit._film_compiled) makes them so
    fn.argtypes = [_L, _P, _P, _P, _F, _L, _P, _P, _P, _P, _P, _INT, _F, _F, _L, _F, _L, _F]
    fn.argtypes += [_P] * 13
    return fn
