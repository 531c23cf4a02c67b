"""CPU time of one banded Newton-matrix build (element Jacobians, `jacobian="analytic"`, against
coloured differences), planar cubic 2:1 elevator and the spatial cubic crane, at one state 1 mm off
the initial geometry; optionally the same in another checkout, alternated in fresh processes.

    python benchmarks/newton_matrix_cost.py [--baseline OTHER_CHECKOUT] [--rounds 3]
"""
from __future__ import annotations

import argparse
import json
import os
from pathlib import Path
import subprocess
import sys
import time

ROOT = Path(__file__).resolve().parents[1]


def measure(repeat=20):
    """us of CPU time per build (best of `repeat`) per case, in this process's checkout."""
    import numpy as np
    sys.path.insert(0, str(Path.cwd() / "benchmarks"))     # the measured checkout's (cwd) helpers
    from scaling import crane, elevator
    from reeve_fmu.core.jacobian import newton_matrix_analytic
    from reeve_fmu.core.model import build_model, new_state
    from reeve_fmu.core.sparse import build_sparse, jac_shape, newton_matrix_sparse
    from reeve_fmu.core.system import workspace
    out = {}
    cases = (("elevator cubic 16", lambda: elevator(16)), ("elevator cubic 64", lambda: elevator(64)),
             ("crane cubic 4", lambda: _cubic(crane(4))))
    for name, make in cases:
        m = build_model(make())
        SP = build_sparse(m.K)
        st = new_state(m)
        rng = np.random.default_rng(1)
        q = st.q + 1e-3 * rng.standard_normal(m.nq)
        v = 0.1 * rng.standard_normal(m.nq)
        a = rng.standard_normal(m.nq)
        J = np.zeros(jac_shape(SP))
        W = workspace(m.KJ, st.arrays(), False)
        u = np.zeros(7)
        args = (m.KJ, SP, W, st.c, q, v, a, 0.0, u)

        def analytic():
            newton_matrix_analytic(*args, J, np.empty(m.nq), 1.0, 2.5e-7, 5e-4)

        def coloured():
            newton_matrix_sparse(*args, J, np.empty(m.nq), np.empty(m.nq), np.empty(SP.n), 1.0, 2.5e-7, 5e-4, 1e-10)
        for kind, f in (("analytic", analytic), ("coloured", coloured)):
            f()
            best = float("inf")
            for _ in range(repeat):
                t0 = time.process_time()
                f()
                best = min(best, time.process_time() - t0)
            out[f"{name} {kind}"] = dict(nq=int(m.nq), us=best * 1e6)
    return out


def _cubic(sc):
    return sc.with_overrides(ropes=tuple(r.__class__(**{**r.__dict__, "element": "cubic"}) for r in sc.ropes))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baseline", default=None)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.child:
        print(json.dumps(measure()))
        return
    trees = [("this", ROOT)] + ([("baseline", Path(a.baseline).resolve())] if a.baseline else [])
    best = {}
    for _ in range(a.rounds):
        for tag, root in trees:
            env = dict(os.environ, PYTHONPATH=str(root))
            res = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--child"], env=env, cwd=str(root),
                                 capture_output=True, text=True, check=True)
            for k, r in json.loads(res.stdout.strip().splitlines()[-1]).items():
                key = (tag, k)
                best[key] = min(best.get(key, float("inf")), r["us"])
    print(f"load average {os.getloadavg()[0]:.1f}; CPU us per Newton-matrix build (best)")
    for (tag, k), us in sorted(best.items(), key=lambda x: (x[0][1], x[0][0])):
        extra = ""
        if tag == "this" and ("baseline", k) in best:
            extra = f"  (x{us / best[('baseline', k)]:.2f} of baseline)"
        print(f"  {tag:8s} {k:28s} {us:10.0f}{extra}")


if __name__ == "__main__":
    main()
