"""Banded Newton matrix (core/sparse.py): the coloured-difference matrix against one finite difference
per coordinate through the dense assembly, the bordered band LU against numpy, the structural check,
and the sparse path's trajectories against the dense path's."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from benchmarks.scaling import crane, elevator
from reeve_fmu.core.model import build_model, new_state
from reeve_fmu.core.scene import Drive, load_scene
from reeve_fmu.core.solver import Simulator
from reeve_fmu.core.solver.inputs import kernel_inputs_at
from reeve_fmu.core.sparse import (_at, bordered_factor, bordered_solve, build_sparse, jac_shape,
                                   newton_matrix_sparse, pattern_leaks, unpack_dense)
from reeve_fmu.core.system import assemble, workspace
from tests.support import ROOT
from tests.support.checks import check, check_min

SPREAD = "the cases' errors differ by more than 10x: one bound for all"
ROUNDOFF = "round-off, which differs by platform"


def _eps(path, eps, **kw):
    sc = load_scene(path)
    ropes = tuple(r.__class__(**{**r.__dict__, "elements_per_span": eps}) for r in sc.ropes)
    return sc.with_overrides(ropes=ropes, **kw)


def _w2(eps):
    sc = elevator(eps)
    return sc.with_overrides(ropes=tuple(r.__class__(**{**r.__dict__, "wrap_model": "W2"}) for r in sc.ropes))


MODELS = {
    "1d-linear": lambda: _eps(ROOT / "scenes" / "elevator_2to1.toml", 8),
    "planar-linear": lambda: _eps(ROOT / "scenes" / "elevator_2to1.toml", 8, model="planar"),
    "planar-cubic-W1": lambda: elevator(8),
    "planar-cubic-W2": lambda: _w2(6),
    "spatial-linear-crane": lambda: crane(4),
    "1d-traction-slip": lambda: _eps(ROOT / "scenes" / "hard" / "traction_en81.toml", 8),
    "1d-drum": lambda: _eps(ROOT / "tests" / "scenes" / "drum_hoist.toml", 16),
}


def _dense_matrix(m, SP, S, c, q, v, qdd, ue, bq, gv):
    """d r / d qdd_free with one forward difference per coordinate through the dense assembly."""
    M = np.empty((m.nq, m.nq))
    Q = np.empty(m.nq)
    free = SP.perm

    def r(qq, vv, aa):
        assemble(m.KJ, S, c, qq, vv, 0.0, ue, M, Q)
        return (M @ aa - Q)[free]
    r0 = r(q, v, qdd)
    A = np.empty((SP.n, SP.n))
    for jb, j in enumerate(free):
        dx = 1e-10 * (1.0 + abs(q[j])) / bq
        qq, vv, aa = q.copy(), v.copy(), qdd.copy()
        qq[j] += bq * dx
        vv[j] += gv * dx
        aa[j] += dx
        A[:, jb] = (r(qq, vv, aa) - r0) / dx
    return A


@pytest.mark.parametrize("contact", ["rigid", "creep"])
@pytest.mark.parametrize("name", list(MODELS))
def test_coloured_matrix_equals_per_coordinate_differences(name, contact):
    """At a random state (positions off equilibrium by 1 mm, so tension-only spans are partly slack,
    random velocities and accelerations) every entry of the coloured-difference Newton matrix equals
    the per-coordinate forward difference of the dense assembly: the same perturbation of the same
    residual rows, so only the summation order differs. On the creep contact the rim speed, the rim
    inertia and the creep force follow the end strains of the spans at the sheave: the structural
    pattern holds those couplings, so they are separated by the colouring too."""
    m = build_model(dataclasses.replace(MODELS[name](), sheave_contact=contact))
    SP = build_sparse(m.K)
    rng = np.random.default_rng(7)
    st = new_state(m)
    q = st.q + 1e-3 * rng.standard_normal(m.nq)
    v = 0.1 * rng.standard_normal(m.nq)
    qdd = rng.standard_normal(m.nq)
    st.q[:], st.v[:] = q, v
    ue = kernel_inputs_at(m, st)     # with the creep sheaves' kappa and angle at that state
    ue[4] = 1e-4
    bq, gv = 2.5e-7, 5e-4          # h = 1 ms, rho_inf = 1
    J = np.zeros(jac_shape(SP))
    R, R0, dxs = np.empty(m.nq), np.empty(m.nq), np.empty(SP.n)
    assert newton_matrix_sparse(m.KJ, SP, workspace(m.KJ, st.arrays(), False), st.c, q.copy(), v.copy(), qdd.copy(), 0.0,
                                ue, J, R, R0, dxs, 1.0, bq, gv, 1e-10) == 1
    A = _dense_matrix(m, SP, st.arrays(), st.c, q, v, qdd, ue, bq, gv)
    err = np.max(np.abs(unpack_dense(J, SP) - A)) / np.max(np.abs(A))
    check('err', err, 3.3e-10, reason=SPREAD)
    # and the structure is the whole of it: no residual row outside the pattern moves
    assert pattern_leaks(m.KJ, SP, workspace(m.KJ, st.arrays(), False), st.c, q, v, qdd, 0.0, ue, bq, gv) == 0


def test_pattern_check_finds_a_missing_coupling():
    m = build_model(elevator(8))
    SP = build_sparse(m.K)
    # drop every row from one interior column's pattern: perturbing it now moves uncovered rows
    jb = int(SP.grp_cols[SP.grp_ptr[0]])
    rows = SP.col_rows.copy()
    lo, hi = SP.col_ptr[jb], SP.col_ptr[jb + 1]
    rows[lo:hi] = rows[lo]
    st = new_state(m)
    leaks = pattern_leaks(m.KJ, SP._replace(col_rows=rows), workspace(m.KJ, st.arrays(), False), st.c, st.q.copy(),
                          st.v.copy(), st.qdd.copy(), 0.0, np.zeros(7), 2.5e-7, 5e-4)
    assert leaks > 0


@pytest.mark.parametrize("n,nb,kl,ku", [(40, 3, 2, 4), (25, 0, 3, 1), (12, 5, 1, 1)])
def test_bordered_band_lu(n, nb, kl, ku):
    """Band with a dense border, random (not diagonally dominant: pivoting is exercised)."""
    rng = np.random.default_rng(n)
    n1, wb = n - nb, 3 * kl + ku + 1
    A = rng.standard_normal((n, n))
    A[:n1, :n1] *= np.abs(np.subtract.outer(np.arange(n1), np.arange(n1))) <= max(kl, ku)
    A[:n1, :n1] *= ~np.tri(n1, n1, -kl - 1, dtype=bool) & np.tri(n1, n1, ku, dtype=bool)
    J = np.zeros((n, wb + 2 * nb))
    for i, j in zip(*np.nonzero(A)):
        J[_at(i, j, n1, kl, wb, nb)] = A[i, j]
    piv = np.zeros(n, np.int64)
    assert bordered_factor(J, piv, n, nb, kl, ku)
    b = rng.standard_normal(n)
    x = b.copy()
    bordered_solve(J, piv, n, nb, kl, ku, x)
    err = np.max(np.abs(x - np.linalg.solve(A, b))) / np.max(np.abs(x))
    check('err', err, 1e-13, reason=ROUNDOFF)


def _ropes_kw(sc, **kw):
    return sc.with_overrides(ropes=tuple(r.__class__(**{**r.__dict__, **kw}) for r in sc.ropes))


def _braked(eps):
    """Torque-driven traction sheave held by the brake (inputs: torque 0, brake engaged)."""
    sc = _eps(ROOT / "scenes" / "hard" / "slack_hard_stop.toml", eps)
    return sc.with_overrides(drive=Drive(kind="external", sheave="traction", roping=2.0, motor_inertia=2.5))


SCENES = {      # scene, kernel inputs held (None: the scene's own)
    "elevator_2to1": (lambda: _eps(ROOT / "scenes" / "elevator_2to1.toml", 1), None),
    "elevator_2to1_8el_hitch": (lambda: _eps(ROOT / "scenes" / "elevator_2to1.toml", 8), None),
    "elevator_2to1_8el_W0": (lambda: _ropes_kw(_eps(ROOT / "scenes" / "elevator_2to1.toml", 8), wrap_model="W0"),
                             None),
    "brake_held_8el": (lambda: _braked(8), (0.0, 1.0)),
    "highrise_8el": (lambda: _eps(ROOT / "scenes" / "elevator_1to1_highrise.toml", 8), None),
    "hanging_rope_32el": (lambda: _eps(ROOT / "scenes" / "hanging_rope.toml", 32), None),
    "traction_en81_8el": (lambda: _eps(ROOT / "scenes" / "hard" / "traction_en81.toml", 8), None),
    "buffer_impact_8el": (lambda: _eps(ROOT / "scenes" / "hard" / "buffer_impact.toml", 8), None),
    "elevator_planar_cubic_16el": (lambda: elevator(16), None),
}


def _runs(m, sparse, u, perturb=0.0, newton_tol=1e-12):
    """0.5 s from the statics, converged to round-off (newton_tol below solver.genalpha.TOL_ROUNDOFF): outputs
    sampled inside the compiled loop every 10 ms, and evaluated afresh at the converged state every
    50 ms. perturb: relative random change of the free coordinates after the statics (round-off)."""
    sim = Simulator(m, sparse=sparse, newton_tol=newton_tol)
    st = sim.initial_state()
    if perturb:
        f = m.K.free
        st.q[f] *= 1.0 + perturb * np.random.default_rng(1).standard_normal(len(f))
    loop, fresh = [], []
    for _ in range(10):
        loop.append(sim.advance(st, st.t + 0.05, u=u, out_dt=1e-2).values)
        fresh.append(sim.outputs(st))
    assert (sim._sp is not None) == sparse
    return np.vstack(loop), np.array(fresh)


KINEMATIC = ("position", "velocity", "speed", "angle", "slip")   # states and their rates, not forces


def _quantity(name):
    """'car.position.z' -> 'position', 'traction.tension_in' -> 'tension_in'."""
    parts = name.split(".")
    return parts[-2] if len(parts) > 2 and parts[-1] in ("x", "y", "z") else parts[-1]


def _rel(a, b):
    """Per output: largest difference relative to 1 + the output's largest magnitude over the run."""
    return np.max(np.abs(a - b) / (1.0 + np.max(np.abs(b), axis=0)), axis=0)


@pytest.mark.parametrize("name", list(SCENES))
def test_sparse_path_equals_dense_path(name):
    """The first 0.5 s of shipped scenes (8-32 elements per span; the banded path forced on the
    small ones; hitch springs, W0 wraps, a held brake, buffers, groove slip) and the planar cubic
    elevator: the banded path's outputs equal the dense path's, both as sampled in the compiled loop
    and evaluated afresh at the converged states, each output relative to 1 + its largest magnitude
    over the run, to the round-off floor of the problem (test_sparse_difference_is_the_roundoff_floor)."""
    make, u = SCENES[name]
    m = build_model(make())
    (loop_d, fresh_d), (loop_s, fresh_s) = _runs(m, False, u), _runs(m, True, u)
    err, err_loop = _rel(fresh_s, fresh_d), _rel(loop_s, loop_d)
    print(name, "fresh", np.max(err), m.output_names[int(np.argmax(err))], "loop", np.max(err_loop),
          m.output_names[int(np.argmax(err_loop))])
    # the bound is the float64 floor of tensions, torques and accelerations (the dense path against itself
    # with its start changed by one rounding differs as much: test_sparse_difference_is_the_roundoff_floor);
    # it differs by scene by more than 10x, and the brake's stick torque has its own floor (below)
    if "brake.torque" in m.output_names:
        # the loop samples the torque k z of the stick spring (k = T / stick_angle = 1.4e7 N m/rad),
        # z = z0 + gain (s - s0) a difference of rope coordinates s: one rounding of s moves it by
        # k |gain| eps |s| = 1.6e-6 N m, relative to 1 + max|T| (262 N m) the floor 5.9e-9
        K, i = m.K, m.output_names.index("brake.torque")
        s = abs(new_state(m).q[K.mot_dof])    # the rope coordinate at the sheave, 80.3 m (held)
        floor = (K.brake_T / K.brake_wreg * abs(K.mot_gain) * np.finfo(float).eps * s
                 / (1.0 + np.max(np.abs(loop_d[:, i]))))
        print("brake.torque floor", floor)
        check('err_loop[i]', err_loop[i], 2.0 * floor)
        err_loop = np.delete(err_loop, i)
    check('np.max(err_loop)', np.max(err_loop), 1e-9, reason=SPREAD)  # floor
    check('np.max(err)', np.max(err), 1e-9, reason=SPREAD)  # floor
    # positions, velocities, rim speeds, angles and slips agree to 1e-10
    kin = [i for i, n in enumerate(m.output_names) if _quantity(n) in KINEMATIC]
    worst = max(np.max(_rel(loop_s[:, kin], loop_d[:, kin])), np.max(_rel(fresh_s[:, kin], fresh_d[:, kin])))
    check('worst', worst, 1e-10, reason=SPREAD)


def test_sparse_difference_is_the_roundoff_floor():
    """Why the two paths differ by ~1e-10 in tensions and not less, and why no implementation that
    rounds differently can do better than this floor on these outputs.

    High-rise, 8 elements per span, 0.5 s, both paths converged to round-off. The round-off floor of
    an output is how far the dense path itself moves when only the rounding changes: here its start,
    the free coordinates changed by one rounding (2.2e-16 relative, two draws). One ulp of a converged
    state moves the tensions at once: they are EA (6.2e7 N here) times differences of coordinates of
    up to 212 m over elements down to the short spans at the sheaves. The banded path, which sums in
    another order, must stay within that floor (a wrong matrix entry costs only iterations, but a
    wrong residual term or a loose exit would leave it far above), and the floor must be real, not
    zero: then a 1e-10 agreement can hold for positions, velocities, speeds, angles and slips
    (asserted in test_sparse_path_equals_dense_path) but not for tensions, torques and accelerations.

    The Newton tolerance does not change the rounding here: below solver.genalpha.TOL_ROUNDOFF the exit waits
    for the correction to stop shrinking, so 1e-13 stops at the same iterates as 1e-12."""
    make, u = SCENES["highrise_8el"]
    m = build_model(make())
    eps = np.finfo(float).eps
    (loop_d, fresh_d), (loop_s, fresh_s) = _runs(m, False, u), _runs(m, True, u)
    floor = max(max(np.max(_rel(lp, loop_d)), np.max(_rel(fr, fresh_d)))
                for lp, fr in (_runs(m, False, u, perturb=eps), _runs(m, False, u, perturb=-eps)))
    diff = max(np.max(_rel(loop_s, loop_d)), np.max(_rel(fresh_s, fresh_d)))
    check_min("round-off floor: dense path, start changed by one rounding", floor, 5e-11)
    check("round-off floor: dense path, start changed by one rounding", floor, 1e-9)
    check("(banded - dense) / round-off floor", diff / floor, 2.0)


@pytest.mark.parametrize("sparse", [False, True])
def test_fixed_steps_call_the_compiled_entry_point_and_match_advance(sparse):
    """Simulator.step (a co-simulation's fixed steps) calls the stepping kernel's compiled entry point
    for this model's Newton path, dense or banded (numba's argument typing per call would cost more
    than a 1D step), and lands on the states advance() reaches: bit for bit."""
    from reeve_fmu.core._jit import JIT
    m = build_model(_eps(ROOT / "scenes" / "elevator_2to1.toml", 8))
    a, b = Simulator(m, sparse=sparse), Simulator(m, sparse=sparse)
    sa, sb = a.initial_state(), b.initial_state()
    for k in range(1, 6):
        a.step(sa, 1e-3 * k, 0.0, 1.0)
        b.advance(sb, 1e-3 * k, u=(0.0, 1.0))
    assert (a._sp is not None) == sparse
    if JIT:
        assert type(a._fast_integrate).__name__ == "builtin_function_or_method", type(a._fast_integrate)
    assert np.array_equal(sa.q, sb.q) and np.array_equal(sa.v, sb.v)
