"""How locbook compiles its kernels: one decorator for every ``_*kernels.py`` module.

numba is a dependency of locbook, but only the kernel modules import it, and they are imported only when a compiled
path runs (``import locbook`` never loads numba). A kernel is compiled on its first call and its machine code cached
on disk beside the module (``__pycache__``), so later processes load it in about a second; where no cache location
is writable it is compiled in memory at each session. Without numba (a broken install) the decorator returns the
plain Python function: the same arithmetic, slowly (the tests run some kernels that way).
"""
from __future__ import annotations

try:
    import numba
except ImportError:                 # plain Python kernels
    numba = None


def jit(fn=None, *, contract: bool = False, reassoc: bool = False):
    """``fn`` compiled on first call (numba's ``njit``: no GIL, numpy's error model), cached on disk where possible.

    ``contract=True`` allows ``a * b + c`` to become one fused multiply-add (one rounding instead of two; fastmath's
    "contract" licence only: no reassociation, NaN and infinities kept). ``reassoc=True`` (with ``contract``) also
    lets LLVM reassociate, for reductions alone: a sum is then accumulated in vector registers side by side (the
    order is fixed by the compiled code, so the same machine gives the same bits; its error bound is that of as many
    partial sums). Usable as ``@jit`` or ``@jit(contract=True)``.
    """
    if fn is None:
        return lambda f: jit(f, contract=contract, reassoc=reassoc)
    if numba is None:
        return fn
    options = dict(nogil=True, error_model="numpy")
    if contract or reassoc:
        options["fastmath"] = {"contract", "reassoc"} if reassoc else {"contract"}
    try:
        return numba.njit(cache=True, **options)(fn)
    except RuntimeError:            # no writable cache location: compile in memory at each session
        return numba.njit(**options)(fn)
