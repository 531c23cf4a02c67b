"""Numba JIT with a pure-Python fallback.

The element kernels and the step loop are written in the subset of Python that numba compiles. With
numba installed (a declared dependency) they run compiled; where it is missing (an FMU imported into an
interpreter without numba) or REEVE_FMU_NO_JIT=1, the same code runs as plain Python: identical
results, roughly 100x slower.
"""
from __future__ import annotations

import os

JIT = os.environ.get("REEVE_FMU_NO_JIT", "") not in ("1", "true", "yes")

try:
    if not JIT:
        raise ImportError
    import numba as _numba
except ImportError:  # pragma: no cover - exercised only without numba
    _numba = None
    JIT = False


def njit(*args, **kwargs):
    """numba.njit when available, otherwise the identity decorator."""
    if _numba is not None:
        # numpy error model: float division by zero gives inf/nan instead of a branch + exception
        # on every division (measurably faster in the element kernels); callers check finiteness.
        kwargs.setdefault("error_model", "numpy")
        return _numba.njit(*args, **kwargs)
    if len(args) == 1 and callable(args[0]) and not kwargs:
        return args[0]
    return lambda f: f
