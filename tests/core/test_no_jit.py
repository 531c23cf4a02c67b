"""The kernels without numba (REEVE_FMU_NO_JIT=1, or an interpreter without numba, as in an FMU host):
the same code runs as plain Python and must give the compiled kernels' results bit for bit
(reeve_fmu/core/_jit.py, docs/fmu-hosts.md). Each run is its own interpreter, since the switch is read
at import."""
from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from reeve_fmu.core import _jit
from tests.support import ROOT

RUN = r"""
import sys
import numpy as np
import reeve_fmu
from reeve_fmu.core import _jit, system
scene, t_end, out = sys.argv[1], float(sys.argv[2]), sys.argv[3]
sets = dict(a.split("=", 1) for a in sys.argv[4:])
sets = {k: (int(v) if v.isdigit() else v) for k, v in sets.items()}
r = reeve_fmu.simulate(scene, t_end=t_end, dt=0.01, overrides=sets)
compiled = hasattr(system.assemble, "py_func")        # a numba dispatcher, not the plain function
np.savez(out, __jit__=np.array([_jit.JIT, compiled]), __time__=r.time, **{n: np.asarray(r[n]) for n in r.columns})
"""

#: the start of the 2:1 trip (the car starts at 0.5 s): 1.5 s in the 1-D model with linear elements, 1 s of
#: the same scene planar with two cubic elements per span
CASES = {
    "elevator_2to1": ("scenes/elevator_2to1.toml", 1.5, ()),
    "elevator_2to1_planar_cubic": ("scenes/elevator_2to1.toml", 1.0,
                                   ("scene.model=planar", "rope.element=cubic", "rope.elements_per_span=2")),
}


def _run(tmp_path, case, no_jit):
    scene, t_end, sets = CASES[case]
    out = tmp_path / f"{case}-{'plain' if no_jit else 'jit'}.npz"
    env = {k: v for k, v in os.environ.items() if k != "REEVE_FMU_NO_JIT"}
    if no_jit:
        env["REEVE_FMU_NO_JIT"] = "1"
    p = subprocess.run([sys.executable, "-c", RUN, scene, str(t_end), str(out), *sets], cwd=ROOT, env=env,
                       capture_output=True, text=True, timeout=1800)
    assert p.returncode == 0, p.stdout + p.stderr
    with np.load(out) as z:
        return {k: z[k] for k in z.files}


@pytest.mark.skipif(not _jit.JIT, reason="REEVE_FMU_NO_JIT=1 or numba not installed: no compiled kernels to "
                                         "compare the plain-Python run with")
@pytest.mark.parametrize("case", list(CASES))
def test_plain_python_kernels_give_the_compiled_results_bit_for_bit(case, tmp_path):
    jit, plain = _run(tmp_path, case, False), _run(tmp_path, case, True)
    assert jit.pop("__jit__").tolist() == [True, True]        # numba on, the kernels compiled
    assert plain.pop("__jit__").tolist() == [False, False]    # the switch took: plain Python
    assert sorted(jit) == sorted(plain) and len(jit) > 20
    car = next(k for k in jit if k.startswith("car.position"))      # car.position, or .z in the planar model
    assert np.ptp(jit[car]) > 1e-3                            # the car moved: the run is not a rest state
    for name, a in jit.items():
        b = plain[name]
        assert a.shape == b.shape and a.tobytes() == b.tobytes(), (
            f"{name}: plain Python differs from the compiled kernels by {np.max(np.abs(a - b)):.3g}")
