"""Cost per time step against model size: banded (sparse) Newton matrix against the dense one.

Cases: the R1 2:1 elevator (scenes/elevator_2to1.toml) in the planar model with cubic elements at
1-128 elements per span, and the 8-fall crane hoist (scenes/crane_8fall.toml run dynamically: spatial
model, linear elements, 65 t on the block released at rest, drum hoisting on an S-curve) at 2-64
elements per span.
Per case: statics, a 10-step warm-up (first Newton matrix), then the best of three consecutive
`--window` s of generalized-alpha steps (h = 1 ms), Newton-matrix rebuilds in them included; banded
cases twice: Newton matrix from element Jacobians (the default) and from coloured differences. The
dense path is timed up to `--dense-max` elements per span. Ratios come from one run, with the load average.
Writes DIR/scaling.json and the log-log plot DIR/scaling.png.

    python benchmarks/scaling.py --out docs/img          # full (docs/performance.md), ~10 min
    python benchmarks/scaling.py --quick --out /tmp/sc    # 1-32 elements per span, ~1 min
    python benchmarks/scaling.py --baseline ../main --trip-only   # 1D trip against another checkout
    python benchmarks/scaling.py --rest-or-moving     # 8-32 el/span: window at rest vs during the trip
"""
from __future__ import annotations

import argparse
import json
import os
from pathlib import Path
import sys
import time

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from reeve_fmu.core.model import build_model  # noqa: E402
from reeve_fmu.core.scene import Drive, load_scene  # noqa: E402
from reeve_fmu.core.solver import Simulator  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def elevator(eps):
    sc = load_scene(ROOT / "scenes" / "elevator_2to1.toml")
    ropes = tuple(r.__class__(**{**r.__dict__, "elements_per_span": eps, "element": "cubic"}) for r in sc.ropes)
    return sc.with_overrides(ropes=ropes, model="planar")


def crane(eps):
    """The 8-fall hoist as a dynamic scene: 65 t hook load lifted by the drum (S-curve, 0.5 m/s)."""
    sc = load_scene(ROOT / "scenes" / "crane_8fall.toml")
    # the block translates only and the rope has no torsion: the axial 8-fall crane (frozen tangents)
    ropes = tuple(r.__class__(**{**r.__dict__, "elements_per_span": eps, "torsion": None, "length": None})
                  for r in sc.ropes)
    block = sc.bodies[0].__class__(**{**sc.bodies[0].__dict__, "mass": 65000.0, "free": ("x", "y", "z")})
    drive = Drive(kind="speed", sheave="drum", roping=8.0, distance=-2.0, v_max=0.5, a_max=0.3, jerk=0.5,
                  t_start=0.0)
    # released at rest from the geometry (statics "none"): the static Newton from the geometric guess
    # is singular for some meshes (straight unloaded spans in the spatial model)
    return sc.with_overrides(ropes=ropes, bodies=(block,), drive=drive, model="spatial", statics="none",
                             tangents="frozen")


def time_case(scene, sparse, window, repeat=3, jacobian="analytic", skip=0.01):
    m = build_model(scene)
    sim = Simulator(m, sparse=sparse, step=1e-3, jacobian=jacobian)
    t0 = time.perf_counter()
    st = sim.initial_state()
    statics = time.perf_counter() - t0
    sim.advance(st, st.t + skip)
    wall = float("inf")
    for _ in range(repeat):     # best of `repeat` consecutive windows (the machine is shared)
        n0, j0, i0 = st.info[1], st.info[3], st.info[2]
        t0 = time.perf_counter()
        sim.advance(st, st.t + window)
        w = time.perf_counter() - t0
        if w < wall:
            wall, steps, its, jacs = w, st.info[1] - n0, st.info[2] - i0, st.info[3] - j0
    SP = sim._sp
    return dict(nq=int(m.nq), nf=int(len(m.K.free)), path="dense" if SP is None else "banded",
                kl=SP.kl if SP else None, ku=SP.ku if SP else None,
                groups=int(len(SP.grp_ptr) - 1) if SP else None, statics_s=statics,
                us_per_step=wall / steps * 1e6, jac_builds=int(jacs), steps=int(steps),
                iter_per_step=its / steps, us_per_iter=wall / its * 1e6)


def lu_comparison(eps=64, repeat=20):
    """Factor + solve of one Newton matrix of the elevator at eps elements per span: the compiled
    bordered band LU against scipy's SuperLU (splu, COLAMD ordering) and dense LAPACK."""
    import numpy as np
    from scipy.sparse.linalg import splu
    from reeve_fmu.core.model import new_state
    from reeve_fmu.core.sparse import (bordered_factor, bordered_solve, build_sparse, jac_shape,
                                       newton_matrix_sparse, unpack_sparse)
    from reeve_fmu.core.system import workspace
    m = build_model(elevator(eps))
    SP = build_sparse(m.K)
    st = new_state(m)
    J = np.zeros(jac_shape(SP))
    newton_matrix_sparse(m.KJ, SP, workspace(m.KJ, st.arrays(), False), st.c, st.q.copy(), st.v.copy(), st.qdd.copy(), 0.0,
                         np.zeros(7), J, np.empty(m.nq), np.empty(m.nq), np.empty(SP.n), 1.0, 2.5e-7, 5e-4, 1e-10)
    A = unpack_sparse(J, SP).tocsc()
    b = np.ones(SP.n)
    piv = np.zeros(J.shape[0], np.int64)

    def best(f):
        f()
        t = []
        for _ in range(repeat):
            t0 = time.perf_counter()
            f()
            t.append(time.perf_counter() - t0)
        return min(t) * 1e6

    def banded():
        Jc = J.copy()
        bordered_factor(Jc, piv, SP.n, SP.nb, SP.kl, SP.ku)
        x = b.copy()
        bordered_solve(Jc, piv, SP.n, SP.nb, SP.kl, SP.ku, x)
    Jf = J.copy()
    bordered_factor(Jf, piv, SP.n, SP.nb, SP.kl, SP.ku)
    lu = splu(A)
    Ad = A.toarray()
    res = dict(nq=int(m.nq), banded_factor_solve_us=best(banded),
               banded_solve_us=best(lambda: bordered_solve(Jf, piv, SP.n, SP.nb, SP.kl, SP.ku, b.copy())),
               splu_factor_solve_us=best(lambda: splu(A).solve(b)), splu_solve_us=best(lambda: lu.solve(b)),
               dense_factor_solve_us=best(lambda: np.linalg.solve(Ad, b)))
    print("LU at", eps, "el/span:", {k: round(v, 1) if isinstance(v, float) else v for k, v in res.items()})
    return res


def trip_1d(baseline, rounds=3):
    """The 1D 2:1 trip (benchmarks/trip_2to1.py, best of 5 inside) of this tree and of a baseline
    checkout, alternated `rounds` times in fresh processes: us per step of each (best per tree)."""
    import re
    import subprocess
    best = {}
    for _ in range(rounds):
        for name, root in (("this", ROOT), ("baseline", Path(baseline))):
            out = subprocess.run([sys.executable, str(root / "benchmarks" / "trip_2to1.py")], capture_output=True,
                                 text=True, cwd=str(root), check=True).stdout
            us = float(re.search(r"\(([0-9.]+) us/step", out).group(1))
            best[name] = min(best.get(name, float("inf")), us)
    print(f"1D 2:1 trip: {best['this']:.2f} us/step here, {best['baseline']:.2f} us/step in {baseline} "
          f"(ratio {best['this'] / best['baseline']:.3f}, load {os.getloadavg()[0]:.1f})")
    return best


def at_rest_or_moving(epss=(8, 16, 32), window=0.1):
    """The elevator's per-step cost right after the statics (ropes at rest, as in the scaling table)
    against a window during the trip (from t = 2 s, car moving): is a mesh's outlier a state at rest?"""
    for eps in epss:
        r0 = time_case(elevator(eps), None, window)
        r1 = time_case(elevator(eps), None, window, skip=2.0)
        print(f"elevator {eps:3d} el/span nq {r0['nq']:5d}: at rest {r0['us_per_step']:7.0f} us/step "
              f"({r0['iter_per_step']:.2f} it/step, {r0['us_per_iter']:.0f} us/it), moving {r1['us_per_step']:7.0f} "
              f"us/step ({r1['iter_per_step']:.2f} it/step, {r1['us_per_iter']:.0f} us/it), "
              f"load {os.getloadavg()[0]:.1f}", flush=True)


def plot(rows, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    for case, mk in (("elevator 2:1 planar cubic", "o"), ("crane 8-fall spatial", "s")):
        for kind, ls in (("banded", "-"), ("dense", "--")):
            pts = sorted((r["nq"], r["us_per_step"]) for r in rows if r["case"] == case and r["path"] == kind)
            if pts:
                ax.loglog(*zip(*pts), ls, marker=mk, label=f"{case}, {kind}")
    ax.set_xlabel("generalized coordinates")
    ax.set_ylabel("wall time per step [µs]")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--out", default=None, help="directory for scaling.json and scaling.png")
    ap.add_argument("--window", type=float, default=0.1, help="timed simulated seconds per case")
    ap.add_argument("--dense-max", type=int, default=None, help="largest elements/span timed dense")
    ap.add_argument("--baseline", default=None, help="another checkout: compare the 1D 2:1 trip speed with it")
    ap.add_argument("--trip-only", action="store_true", help="only the 1D trip comparison (--baseline)")
    ap.add_argument("--rest-or-moving", action="store_true", help="only the at-rest/moving windows at 8-32 el/span")
    a = ap.parse_args(argv)
    if a.rest_or_moving:
        at_rest_or_moving()
        return
    if a.baseline:
        trip_1d(a.baseline)
        if a.trip_only:
            return
    el_eps = [1, 2, 4, 8, 16, 32] if a.quick else [1, 2, 4, 8, 16, 32, 64, 128]
    cr_eps = [2, 4, 8, 16] if a.quick else [2, 4, 8, 16, 32, 64]
    dense_max = a.dense_max or (16 if a.quick else 64)
    # the crane starts from rest and rebuilds its Newton matrix every other step: dense costs minutes
    # per case above 16 elements per span
    dense_max_case = {"elevator 2:1 planar cubic": dense_max, "crane 8-fall spatial": min(dense_max, 16)}
    time_case(elevator(1), None, 0.01)      # JIT load
    rows = []
    for case, make, epss in (("elevator 2:1 planar cubic", elevator, el_eps), ("crane 8-fall spatial", crane, cr_eps)):
        for eps in epss:
            for sparse in (None, False):
                if sparse is False and eps > dense_max_case[case]:
                    continue
                r = time_case(make(eps), sparse, a.window)
                if sparse is False and r["path"] == "dense" and rows and rows[-1]["path"] == "dense" \
                        and rows[-1]["nq"] == r["nq"]:
                    continue    # the automatic choice was dense already
                if r["path"] == "banded":      # the same case with the coloured-difference Newton matrix
                    rc = time_case(make(eps), sparse, a.window, jacobian="coloured")
                    r.update(us_per_step_coloured=rc["us_per_step"], jac_builds_coloured=rc["jac_builds"],
                             iter_per_step_coloured=rc["iter_per_step"])
                r.update(case=case, elements_per_span=eps, load=os.getloadavg()[0])
                rows.append(r)
                print(f"{case:28s} {eps:4d} el/span nq {r['nq']:5d} {r['path']:6s} "
                      f"band ({r['kl']}, {r['ku']}) groups {r['groups']}  {r['us_per_step']:10.0f} us/step "
                      f"({r['iter_per_step']:.2f} it/step, {r['us_per_iter']:.0f} us/it, jac builds {r['jac_builds']}/{r['steps']})  statics {r['statics_s']:.2f} s  "
                      f"{'coloured: %.0f us/step, %.2f it/step  ' % (r['us_per_step_coloured'], r['iter_per_step_coloured']) if 'us_per_step_coloured' in r else ''}"
                      f"load {r['load']:.1f}", flush=True)
    for case in ("elevator 2:1 planar cubic", "crane 8-fall spatial"):
        sp = [r for r in rows if r["case"] == case and r["path"] == "banded"]
        for r0, r1 in zip(sp, sp[1:]):
            print(f"{case}: {r0['nq']} -> {r1['nq']} coordinates (x{r1['nq'] / r0['nq']:.2f}): per-step cost "
                  f"x{r1['us_per_step'] / r0['us_per_step']:.2f}, per coordinate "
                  f"x{r1['us_per_step'] / r1['nq'] / (r0['us_per_step'] / r0['nq']):.2f}")
        for r in sp:
            d = [x for x in rows if x["case"] == case and x["path"] == "dense" and x["nq"] == r["nq"]]
            if d:
                print(f"{case}: {r['elements_per_span']} el/span: banded {d[0]['us_per_step'] / r['us_per_step']:.1f}x "
                      f"faster than dense")
    lu = lu_comparison(32 if a.quick else 64)
    if a.out:
        out = Path(a.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "scaling.json").write_text(json.dumps(dict(rows=rows, lu=lu), indent=1), encoding="utf-8")
        plot(rows, out / "scaling.png")
        print(f"wrote {out / 'scaling.json'} and {out / 'scaling.png'}")


if __name__ == "__main__":
    main()
