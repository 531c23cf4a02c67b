"""Self-check of numba's on-disk cache for the package as it is loaded in this process.

Inside an FMU the package is served from the stable per-user copy made by the bootstrap shim
(see `_bootstrap`), so the second and later runs must hit numba's cache instead of compiling again.
`jit_cache_probe()` compiles (or loads) a tiny `cache=True` kernel that lives in the package and
reports numba's own hit/miss counters; tests and `reeve-fmu check` can assert on them.
"""
from __future__ import annotations

from ..core._jit import JIT, njit


@njit(cache=True)
def _probe_kernel(n):
    s = 0.0
    for i in range(n):
        s += 0.5 * i
    return s


def jit_cache_probe() -> dict:
    """{'jit', 'value', 'cache_hits', 'cache_misses', 'cache_path', 'module_file'}."""
    value = float(_probe_kernel(10))
    stats = getattr(_probe_kernel, "stats", None)
    return {
        "jit": JIT,
        "value": value,
        "cache_hits": sum(stats.cache_hits.values()) if stats is not None else None,
        "cache_misses": sum(stats.cache_misses.values()) if stats is not None else None,
        "cache_path": getattr(stats, "cache_path", None),
        "module_file": __file__,
    }
