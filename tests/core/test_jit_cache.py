"""numba's on-disk cache across processes (reeve_fmu/core/_jit.py): processes that need the same kernel
at the same moment compile it once; the others load it from the cache."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import time

import pytest

from reeve_fmu.core._jit import JIT as _JIT   # the compiled-kernel cache tests need numba
from tests.support import ROOT

# each process imports the package, says it is ready, waits for "go", then calls the probe kernel
CODE = """
import json, os, sys, time
from reeve_fmu.fmu import jitcheck
open(os.path.join(sys.argv[1], "ready" + sys.argv[2]), "w").close()
while not os.path.exists(os.path.join(sys.argv[1], "go")):
    time.sleep(0.001)
print(json.dumps(jitcheck.jit_cache_probe()))
"""


@pytest.mark.skipif(not _JIT, reason="REEVE_FMU_NO_JIT=1 or numba not installed: the kernels run as plain Python and there is no compiled-kernel cache to test")
def test_processes_starting_together_compile_a_kernel_once(tmp_path):
    """Two processes call the same not-yet-compiled kernel within a millisecond of each other on a
    cold cache: one compiles it (a cache miss), the other waits for it and loads it (a cache hit).
    Without the compile lock both compile it (2 misses, 0 hits)."""
    env = dict(os.environ, REEVE_FMU_CACHE_DIR=str(tmp_path / "cache"), PYTHONPATH=str(ROOT))
    procs = [subprocess.Popen([sys.executable, "-c", CODE, str(tmp_path), str(i)], cwd=ROOT, env=env,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for i in range(2)]
    deadline = time.monotonic() + 600      # hang guard: generous under load
    while not all((tmp_path / f"ready{i}").exists() for i in range(2)):
        assert time.monotonic() < deadline and all(p.poll() is None for p in procs), "a process did not start"
        time.sleep(0.01)
    (tmp_path / "go").touch()
    res = []
    for p in procs:
        out, err = p.communicate(timeout=600)
        assert p.returncode == 0, err
        res.append(json.loads(out))
    assert res[0]["jit"]
    assert sorted((r["cache_misses"], r["cache_hits"]) for r in res) == [(0, 1), (1, 0)]


def test_processes_starting_together_all_find_the_cache(tmp_path, monkeypatch):
    """Every process that starts beside others on an empty cache directory gets that directory and
    its compile locks. With one shared name for the writability probe, a starter could find its probe
    already removed by another and silently run without the cache, compiling every kernel again
    (with one name, 131 of these 400 starts lost the cache)."""
    import threading
    from reeve_fmu.core import _jit

    monkeypatch.setenv("REEVE_FMU_CACHE_DIR", str(tmp_path))
    # hashing the package's sources (0.1 s, reading files: other starters run meanwhile) as a 2 ms wait
    monkeypatch.setattr(_jit, "source_hash", lambda: (time.sleep(0.002), "sources")[1])
    lost = []
    for _ in range(50):
        barrier = threading.Barrier(8)
        found = []

        def start():
            barrier.wait()
            found.append(_jit._cache_dir())

        threads = [threading.Thread(target=start) for _ in range(8)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        lost += [d for d in found if d is None]
    assert not lost, f"{len(lost)} of 400 starts ran without the cache"


STEPPING_SIGNATURES = """
import json, sys
from reeve_fmu.core import kernel
from reeve_fmu.core.model import build_model
from reeve_fmu.core.scene import load_scene
from reeve_fmu.core.solver import Simulator
from reeve_fmu.core.solver.stepping import integrate
from reeve_fmu.core.system import assemble_ws
from reeve_fmu.fmu.kernels import _STEPPING
# plain-Python kernels (no numba) have no signatures: compile_stepping then does nothing
sigs = lambda: [sorted(map(str, getattr(f, "signatures", []))) for f in (integrate, assemble_ws)]
exec(_STEPPING)                      # what the process beside a first run does
before = sigs()
struct_compiled = len(kernel._new_kernel.signatures) if kernel.JIT else 0
Simulator(build_model(load_scene(sys.argv[1]))).run(0.01, 1e-3)
print(json.dumps([before, sigs(), struct_compiled]))
"""


def test_compile_stepping_compiles_what_a_run_uses():
    """The process a first demo starts beside itself (Simulator.compile_stepping on a model built without
    its compiled struct) compiles the assembly and the stepping kernel with the signatures a run of the
    scene calls: in a fresh interpreter, a run after it adds no specialization of either (a mismatch
    would compile them a second time), and it does not compile the struct's constructor.
    Without numba it compiles nothing and the run goes on in plain Python."""
    p = subprocess.run([sys.executable, "-c", STEPPING_SIGNATURES, str(ROOT / "scenes" / "elevator_2to1.toml")],
                       cwd=ROOT, capture_output=True, text=True, timeout=900)
    assert p.returncode == 0, p.stderr[-3000:]
    before, after, struct_compiled = json.loads(p.stdout.strip().splitlines()[-1])
    assert [len(s) for s in before] == ([1, 1] if _JIT else [0, 0])
    assert after == before
    assert struct_compiled == 0      # types only: the kernel struct's constructor is left to the run
