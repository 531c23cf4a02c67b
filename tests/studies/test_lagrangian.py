"""Lagrangian finite-element baseline (reeve_fmu/studies/lagrangian.py) and the work-precision bench, against
exact results (docs/theory.md §7) and the ALE engine. Short runs only: speed is measured by the bench, not here."""
import math

import numpy as np
import pytest
from scipy.linalg import eigh
from scipy.optimize import brentq

from reeve_fmu.studies import bench
from reeve_fmu.studies import lagrangian as lag
from reeve_fmu.studies.lagrangian_kernels import dense_matrices
from reeve_fmu.core.scene import load_scene
from tests.support import ROOT
from tests.support.checks import check_png
from tests.support.checks import check

ROUNDOFF = "round-off, which differs by platform"

HANGING = ROOT / "scenes" / "hanging_rope.toml"


def _hanging(statics=None):
    sc = load_scene(HANGING)
    return sc if statics is None else sc.with_overrides(statics=statics)


def test_hanging_static_elongation_exact():
    """docs/theory.md §7 item 1: linear elements with consistent gravity give the exact elongation."""
    sc = _hanging()
    m = lag.build_lagrangian(sc, element_length=10.0, coarse_length=10.0)
    sim = lag.LagrangianSimulator(m)
    st = sim.initial_state()
    y = dict(zip(m.output_names, sim.outputs(st)))
    r, b = sc.ropes[0], sc.bodies[0]
    g = 9.81
    delta = (b.mass * g * r.length + r.rhoA * g * r.length ** 2 / 2) / r.EA
    # round-off of the statics solve
    check('y["mass.position"] - (-delta)', y["mass.position"] - (-delta), 3e-13 * np.max(np.abs((-delta))))
    check('y["rope.tension_end"] - (b.mass * g)', y["rope.tension_end"] - (b.mass * g), 3e-13 * np.max(np.abs((b.mass * g))))
    check('y["rope.tension_start"] - (b.mass * g + r.rhoA * g * r.length)', y["rope.tension_start"] - (b.mass * g + r.rhoA * g * r.length), 2e-12 * np.max(np.abs((b.mass * g + r.rhoA * g * r.length))))


def test_hanging_first_axial_frequency_beta_tan_beta():
    """docs/theory.md §7 item 2: first axial frequency from beta tan beta = rhoA L / m (Newton matrices of
    the baseline at the static state; the planar mesh also has transverse string modes, the axial
    one is picked by its motion)."""
    sc = _hanging()
    m = lag.build_lagrangian(sc, element_length=2.5, coarse_length=2.5)
    sim = lag.LagrangianSimulator(m)
    st = sim.initial_state()
    n = m.n_dof
    M, K, _ = dense_matrices(m.LK, st.q, st.v, 0.0, st.z, np.zeros(n, bool), False)
    w2, vec = eigh(K, M)
    zrow = np.array([nm.endswith(".z") for nm in m.q_names])
    axial = [i for i in range(n) if np.sum(vec[zrow, i] ** 2) > 0.99 * np.sum(vec[:, i] ** 2)]
    w1 = math.sqrt(w2[axial[0]])
    r, b = sc.ropes[0], sc.bodies[0]
    beta = brentq(lambda x: x * math.tan(x) - r.rhoA * r.length / b.mass, 1e-9, math.pi / 2 - 1e-9)
    exact = beta * math.sqrt(r.EA / r.rhoA) / r.length
    check('w1 - exact', w1 - exact, 2e-7 * np.max(np.abs(exact)))


def test_modal_series_reference_meets_its_initial_condition():
    """The bench's exact reference for the release case: u = 0 at t = 0 (mass at its position, no
    tension at the top), and the late-time mean is the static elongation."""
    sc = _hanging("none")
    z, N = bench.hanging_release_exact(sc, np.array([0.0]))
    check('z[0]', z[0], 1e-13)
    check('N[0]', N[0], 1e-4 * 500 * 9.81)  # the series' truncation
    t = np.linspace(0.0, 60.0, 120001)
    zt, _ = bench.hanging_release_exact(sc, t, n_modes=50)
    r, b = sc.ropes[0], sc.bodies[0]
    delta = (b.mass * 9.81 * r.length + r.rhoA * 9.81 * r.length ** 2 / 2) / r.EA
    check('np.mean(zt) - (-delta)', np.mean(zt) - (-delta), 2e-3 * np.max(np.abs((-delta))))


def test_lagrangian_release_follows_the_modal_series():
    # the modal series is that of a linear (bilateral) rope: released from its unstretched length, a
    # tension-only rope's strain starts inside the slack law's smoothing band
    sc = _hanging("none").with_overrides(ropes=tuple(
        r.__class__(**{**r.__dict__, "damping": 0.0, "tension_only": False}) for r in _hanging().ropes))
    m = lag.build_lagrangian(sc, element_length=6.25, coarse_length=6.25)
    sim = lag.LagrangianSimulator(m, step=2.5e-4, rho_inf=1.0, newton_tol=1e-8)
    res = sim.run(0.6, 1e-3)
    z, _ = bench.hanging_release_exact(sc, res.time)
    r, b = sc.ropes[0], sc.bodies[0]
    delta = (b.mass * 9.81 * r.length + r.rhoA * 9.81 * r.length ** 2 / 2) / r.EA   # static elongation
    check('res["mass.position"] - z', res["mass.position"] - z, 5e-5 * 2 * delta)


def test_bench_records_schema(tmp_path):
    """The bench's records, and its errors against the modal series: with two elements and no material
    flow the ALE rope is the Lagrangian linear-element rope, so both methods have the same error."""
    recs = bench.hanging_study(HANGING, quick=True, eps_list=(2,), steps=(1e-3,), t_end=0.05,
                               log=lambda s: None)
    assert {r["method"] for r in recs} == {"ale", "lagrangian"}
    for r in recs:
        for key in ("case", "method", "n_dof", "wall_s", "rtf", "err_position_m", "err_tension_rel"):
            assert key in r, key
        assert r["case"] == "hanging_release"
        assert r["err_position_m"] > 0.0 and r["err_tension_rel"] > 0.0
        check(f"{r['method']}: mass position error [m] (50 ms)", r["err_position_m"], 1e-5)
        check(f"{r['method']}: top tension error / peak (2 elements)", r["err_tension_rel"], 0.1)
    ale, lag_ = sorted(recs, key=lambda r: r["method"])
    # the two methods' errors agree
    check('ale["err_position_m"] - lag_["err_position_m"]', ale["err_position_m"] - lag_["err_position_m"], 5e-10 * np.max(np.abs(lag_["err_position_m"])), reason=ROUNDOFF)
    check('ale["err_tension_rel"] - lag_["err_tension_rel"]', ale["err_tension_rel"] - lag_["err_tension_rel"], 5e-10 * np.max(np.abs(lag_["err_tension_rel"])), reason=ROUNDOFF)
    h = bench.headline(recs, "hanging_release")
    assert h["case"] == "hanging_release"
    figs = bench.plot(recs, tmp_path)
    assert figs
    for f in figs:
        check_png(tmp_path / f)


def test_bad_scene_for_the_baseline_names_the_problem():
    sc = load_scene(ROOT / "scenes" / "elevator_2to1.toml").with_overrides(model="spatial")
    with pytest.raises(Exception, match="planar"):
        lag.build_lagrangian(sc)

