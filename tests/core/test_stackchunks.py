"""The frame-stack chunk keeper that runs during numba compiles (reeve_fmu/core/_stackchunks.py): it is
in place exactly while a compile runs, reuses the 16 KiB chunks CPython would unmap, hands back
CPython's own allocator afterwards, and leaves nothing mapped. Each case runs in a fresh interpreter:
the arena allocator is process-wide."""
from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from reeve_fmu.core import _stackchunks
from reeve_fmu.core._jit import JIT
from tests.support import ROOT

CODE = r"""
import ctypes, json, sys
from reeve_fmu.core import _jit, _stackchunks as sc
from numba import njit
from numba.core import event

def current_ctx():
    a = sc._ArenaAllocator()
    ctypes.pythonapi.PyObject_GetArenaAllocator(ctypes.byref(a))
    return a.ctx

def deep(n):                 # Python calls across many chunk edges, and back
    return 0 if n == 0 else 1 + deep(n - 1)

seen = {"ctx_in": [], "kept_in": [], "depth_sum": 0}
class Probe(event.Listener):
    depth = 0
    def on_start(self, ev):
        Probe.depth += 1
    def on_end(self, ev):
        Probe.depth -= 1
        if Probe.depth == 0:                 # the package's listener has ended the outermost compile
            return
        for _ in range(50):
            seen["depth_sum"] += deep(400)   # ~400 frames: several 16 KiB chunks
        seen["ctx_in"].append(current_ctx())
        seen["kept_in"].append(sc.kept_chunks())
event.register("numba:compile", Probe())

@njit(cache=False)
def inner(x):
    return x * 2.0

@njit(cache=False)
def outer(x):
    return inner(x) + 1.0

ctx_before = current_ctx()
value = outer(3.0)
print(json.dumps({"supported": sc.supported(), "ctx_before": ctx_before, "ctx_after": current_ctx(),
                  "kept_after": sc.kept_chunks(), "value": value, **seen}))
"""


def _run(env_extra=None):
    env = dict(os.environ, PYTHONPATH=str(ROOT), **(env_extra or {}))
    p = subprocess.run([sys.executable, "-c", CODE], cwd=ROOT, env=env, capture_output=True, text=True,
                       timeout=600)
    assert p.returncode == 0, p.stderr[-3000:]
    return json.loads(p.stdout.strip().splitlines()[-1])


NO_JIT = ("REEVE_FMU_NO_JIT=1 or numba not installed: nothing is compiled, so the chunk keeper, which "
          "runs only during numba compiles, is never installed")


@pytest.mark.skipif(not JIT, reason=NO_JIT)
def test_chunks_are_kept_only_while_numba_compiles():
    r = _run()
    assert r["value"] == 7.0
    assert r["ctx_in"] and r["depth_sum"] == 400 * 50 * len(r["ctx_in"])
    assert r["ctx_before"] is None and r["ctx_after"] is None      # CPython's allocator outside compiles
    assert r["kept_after"] == 0                                     # the kept chunks are unmapped
    if r["supported"]:
        assert all(c is not None for c in r["ctx_in"])              # ours during the (nested) compiles
        # the deep recursion's chunks came back to the keeper instead of being unmapped
        assert 1 <= max(r["kept_in"]) <= _stackchunks.KEEP
    else:
        assert set(r["ctx_in"]) == {None}                           # nothing changes on other platforms


@pytest.mark.skipif(not JIT, reason=NO_JIT)
def test_the_keeper_can_be_switched_off():
    r = _run({"REEVE_FMU_KEEP_CHUNKS": "0"})
    assert r["value"] == 7.0 and set(r["ctx_in"]) == {None} and r["kept_after"] == 0
