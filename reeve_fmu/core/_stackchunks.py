"""Keep CPython's frame-stack chunks while numba compiles.

CPython 3.11 and later keep Python frames on per-thread stacks made of 16 KiB chunks, which the
interpreter maps and unmaps through the object arena allocator (mmap/munmap) every time a call crosses
a chunk's edge and returns. numba's compiler is deeply recursive Python code, and on a cold cache it
crosses such an edge back and forth about 1.5 million times while compiling one elevator's kernels:
12-13 s of system time against 38-40 s of user time, a quarter of the compile's CPU.

While a compile runs (numba's "numba:compile" event, outermost only), `install` replaces the arena
allocator with one that keeps up to KEEP freed 16 KiB chunks for reuse and passes every other request
to mmap/munmap exactly as CPython's own allocator does; `uninstall` restores CPython's allocator and
unmaps the kept chunks. Every block either allocator hands out is an anonymous mapping of the requested
size, so each frees what the other allocated. Only on Linux (the mmap flags) with CPython >= 3.11 whose
arena allocator is the default one (no context; PYTHONMALLOC debug hooks or an embedding application's
allocator are left alone), and never in a free-threaded build; elsewhere nothing changes.
"""
from __future__ import annotations

import ctypes
import sys

CHUNK = 16384          # CPython's DATA_STACK_CHUNK_SIZE
KEEP = 64              # chunks kept for reuse (1 MiB at most)
_PROT_RW = 0x3         # PROT_READ | PROT_WRITE
_MAP_PRIVATE_ANON = 0x22


class _ArenaAllocator(ctypes.Structure):
    """CPython's PyObjectArenaAllocator."""
    _fields_ = [("ctx", ctypes.c_void_p), ("alloc", ctypes.c_void_p), ("free", ctypes.c_void_p)]


def supported() -> bool:
    return (sys.platform.startswith("linux") and sys.implementation.name == "cpython"
            and sys.version_info >= (3, 11) and getattr(sys, "_is_gil_enabled", lambda: True)())


_state = {"funcs": None, "saved": None, "keep": None, "ours": None, "depth": 0, "failed": False}


_mmap = _munmap = _carray = _int64 = None     # numba's declarations of the C functions (_compile_funcs)


def _alloc(ctx, size):
    kept = _carray(ctx, KEEP + 1, dtype=_int64)        # kept[0]: count, then the chunks
    n = kept[0]
    if size == CHUNK and n > 0:
        kept[0] = n - 1
        return kept[n]
    p = _mmap(0, size, _PROT_RW, _MAP_PRIVATE_ANON, -1, 0)
    return 0 if p == -1 else p                           # MAP_FAILED -> NULL, as CPython does


def _free(ctx, ptr, size):
    kept = _carray(ctx, KEEP + 1, dtype=_int64)
    n = kept[0]
    if size == CHUNK and n < KEEP:
        kept[n + 1] = ptr
        kept[0] = n + 1
    else:
        _munmap(ptr, size)


def _compile_funcs():
    """The allocator's two functions as C callbacks: they run inside CPython's allocator and must
    not call back into Python."""
    global _mmap, _munmap, _carray, _int64
    import numpy as np
    from numba import carray, cfunc, types

    _carray, _int64 = carray, np.int64
    _mmap = types.ExternalFunction("mmap", types.intp(types.intp, types.size_t, types.intc, types.intc,
                                                      types.intc, types.intp))
    _munmap = types.ExternalFunction("munmap", types.intc(types.intp, types.size_t))
    return (cfunc(types.intp(types.voidptr, types.size_t), cache=True)(_alloc),
            cfunc(types.void(types.voidptr, types.intp, types.size_t), cache=True)(_free))


def install() -> bool:
    """Use the chunk-keeping allocator from now on (idempotent); False where it does not apply."""
    if _state["ours"] is not None:
        return True
    if _state["failed"] or not supported():
        return False
    import numpy as np
    try:
        if _state["funcs"] is None:
            _state["funcs"] = _compile_funcs()
        api = ctypes.pythonapi
        saved = _ArenaAllocator()
        api.PyObject_GetArenaAllocator(ctypes.byref(saved))
        if saved.ctx is not None:          # not CPython's default allocator: leave it alone
            _state["failed"] = True
            return False
        keep = np.zeros(KEEP + 1, np.int64)
        alloc, free = _state["funcs"]
        ours = _ArenaAllocator(keep.ctypes.data, alloc.address, free.address)
        api.PyObject_SetArenaAllocator(ctypes.byref(ours))
    except Exception:                      # no numba, an API that moved: compile as before
        _state["failed"] = True
        return False
    _state.update(saved=saved, keep=keep, ours=ours)
    return True


def uninstall() -> None:
    """Restore CPython's allocator and unmap the chunks kept for reuse."""
    if _state["ours"] is None:
        return
    ctypes.pythonapi.PyObject_SetArenaAllocator(ctypes.byref(_state["saved"]))
    keep = _state["keep"]
    munmap = ctypes.CDLL(None).munmap
    munmap.argtypes = [ctypes.c_void_p, ctypes.c_size_t]
    for i in range(1, int(keep[0]) + 1):
        munmap(int(keep[i]), CHUNK)
    keep[0] = 0
    _state.update(ours=None, keep=None)


def kept_chunks() -> int:
    """Chunks held for reuse now (0 when the allocator is not installed)."""
    return 0 if _state["keep"] is None else int(_state["keep"][0])


def during_compiles() -> None:
    """Install the allocator for the duration of each outermost numba compile."""
    if not supported():
        return
    from numba.core import event

    class _Listener(event.Listener):
        def on_start(self, ev):
            _state["depth"] += 1
            if _state["depth"] == 1:
                install()

        def on_end(self, ev):
            _state["depth"] -= 1
            if _state["depth"] == 0:
                uninstall()

    event.register("numba:compile", _Listener())
