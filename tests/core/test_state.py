"""A step writes only its State (and its own work arrays), never the Model: two Simulators on one
Model, stepped in turn, give each the result of its run alone, to the bit. Scenes: the slewing crane
with its jib on a speed input (nonlinear rows: exact tangents with the contact angles' warm start,
the joint's input table) and the 2:1 elevator (creep traction sheave, speed drive)."""
from __future__ import annotations

import numpy as np

from reeve_fmu.components.plant import JointInput, with_joint_input
from reeve_fmu.core.model import State, build_model
from reeve_fmu.core.scene import load_scene
from reeve_fmu.core.solver import Simulator
from tests.support import ROOT


def _crane():
    scene = with_joint_input(load_scene(ROOT / "scenes" / "slewing_crane.toml"), "jib", "speed")
    m = build_model(scene)
    return m, JointInput(m, next(b for b in scene.bodies if b.name == "jib"))


def _runs(m, plans, interleaved, joint=None):
    """Outputs after every step of each plan (dt, steps, joint speed), the plans' Simulators and
    States stepped in turn (interleaved) or one after the other."""
    runs = []
    for dt, n, speed in plans:
        sim = Simulator(m)
        runs.append((sim, sim.initial_state(), dt, n, speed, []))

    def step(run):
        sim, st, dt, n, speed, out = run
        if joint is not None:
            joint.set(st, dt, speed)
        out.append(sim.step(st, st.t + dt, 0.0, 1.0).copy())
    if interleaved:
        for k in range(max(p[1] for p in plans)):
            for run in runs:
                if k < run[3]:
                    step(run)
    else:
        for run in runs:
            for _ in range(run[3]):
                step(run)
    return [np.array(run[5]) for run in runs], [run[1] for run in runs]


def _same(a: State, b: State) -> bool:
    return a.t == b.t and all(np.array_equal(getattr(a, f), getattr(b, f), equal_nan=True)
                              for f in ("q", "v", "a", "qdd", "c", "info", "el_coef", "nl_ang", "tq_dref",
                                        "jp_prof", "jt_tab"))


def test_two_simulators_on_one_crane_model_step_independently():
    """The jib slews at +0.05 and -0.04 rad/s (speed input, 5 ms steps, 0.4 s) while the payload
    swings; the two runs share the Model and are stepped in turn."""
    m, jib = _crane()
    plans = [(5e-3, 80, 0.05), (5e-3, 80, -0.04)]
    alone, st_alone = _runs(m, plans, interleaved=False, joint=jib)
    both, st_both = _runs(m, plans, interleaved=True, joint=jib)
    assert not np.array_equal(alone[0], alone[1])          # the two runs differ
    assert m.K.nl_on & 1 and np.any(np.isfinite(st_alone[0].nl_ang))   # exact tangents with a warm start
    for a, b in zip(alone, both):
        assert np.array_equal(a, b)
    for a, b in zip(st_alone, st_both):
        assert _same(a, b)


def test_two_simulators_on_one_creep_elevator_model_step_independently():
    """The 2:1 elevator's trip (creep traction sheave) in 1 ms and in 2 ms communication steps over
    0.6 s, the two Simulators stepped in turn."""
    m = build_model(load_scene(ROOT / "scenes" / "elevator_2to1.toml"))
    assert len(m.K.crp_s) > 0
    plans = [(1e-3, 600, 0.0), (2e-3, 300, 0.0)]
    alone, st_alone = _runs(m, plans, interleaved=False)
    both, st_both = _runs(m, plans, interleaved=True)
    for a, b in zip(alone, both):
        assert np.array_equal(a, b)
    for a, b in zip(st_alone, st_both):
        assert _same(a, b)


def test_state_round_trip_keeps_shapes():
    """State.to_dict / from_dict (the FMU state) restores every array with its shape, empty ones
    included (the elevator has no nonlinear rows: nl_ang is 0 x 2)."""
    m = build_model(load_scene(ROOT / "scenes" / "elevator_2to1.toml"))
    st = Simulator(m).initial_state()
    back = State.from_dict(st.to_dict())
    assert back.nl_ang.shape == st.nl_ang.shape == (0, 2)
    assert _same(st, back)
