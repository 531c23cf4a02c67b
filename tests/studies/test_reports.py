"""Reports say what ran: every effective parameter (after --set, the load and the drive sizing) in
summary.json and report.md, and one sign convention for the hoist torque of crane scenes in
`simulate` and the crane FMUs."""
from __future__ import annotations

import json

import numpy as np
import pytest

from reeve_fmu.cli import main
from tests.support import ROOT
from tests.support.checks import check

R1 = ROOT / "scenes" / "elevator_2to1.toml"


def test_trip_parameters_are_the_effective_ones():
    from reeve_fmu.studies.trip import run_parameters, trip_case

    case = trip_case(R1, load=400.0, sets={"rope.EA": 3.0e6, "brake.torque": 1500.0, "torque.max": 1500.0,
                                           "drive.level": 2})
    p = run_parameters(case)
    assert p["scene"]["ropes"]["hoist"]["EA"] == 3.0e6 and p["scene"]["brake"]["torque"] == 1500.0
    assert p["scene"]["bodies"]["car"]["mass"] == 2300.0 - 1000.0 + 400.0      # the trip's load in the car
    assert p["plant"] == {"car.load": 400.0}
    assert p["drive"]["torque.max"] == 1500.0 and p["drive"]["drive.level"] == 2
    assert p["drive"]["control.Kp"] == case.sizing["control.Kp"]             # sized values are there too
    assert p["scene"]["ropes"]["hoist"]["route"][0]["hitch_stiffness"] == 60e3    # defaults and file values
    json.dumps(p)


def test_simulate_writes_every_scene_parameter(tmp_path, capsys):
    scene = ROOT / "scenes" / "hanging_rope.toml"
    rc = main(["simulate", str(scene), "--set", "ropes.rope.EA=3.1e6", "--t-end", "0.002", "--out", str(tmp_path)])
    assert rc == 0, capsys.readouterr().err
    s = json.loads((tmp_path / "summary.json").read_text(encoding="utf-8"))
    assert s["parameters"]["scene"]["ropes"]["rope"]["EA"] == 3.1e6
    assert s["parameters"]["scene"]["solver"]["min_span"] == 0.01            # a default the file leaves out
    md = (tmp_path / "report.md").read_text(encoding="utf-8")
    assert "## Parameters" in md and "| `ropes.rope.EA` | 3.1e+06 |" in md and "| `bodies.mass.mass` | 500 |" in md


def test_crane_simulate_has_the_crane_fmu_sign():
    """simulate and the crane plant FMU give the hoist torque one sign: positive hoists. The slewing crane's
    reel hauls in (hoists) with the engine's negative rotation; simulate's motor.torque at rest equals the
    crane plant's holding torque (the same statics), and motor.speed is positive
    while the payload rises."""
    import reeve_fmu
    from reeve_fmu.components.craneplant import CranePlant
    from reeve_fmu.core.scene import load_scene

    scene = ROOT / "scenes" / "slewing_crane.toml"
    r = reeve_fmu.simulate(scene, t_end=3.0, dt=0.1)
    cp = CranePlant(load_scene(scene), "torque")
    assert cp.hoist_sign == -1.0                                   # the engine's sign is the other one
    check("simulate's torque at rest / the crane plant's holding torque - 1", r["motor.torque"][0] / cp.holding_torque() - 1,
          1e-11, reason="the same statics solved twice: round-off, which differs by platform")
    assert r["motor.torque"][0] > 0
    assert r["motor.speed"][-1] > 0 and r["payload.position.z"][-1] > r["payload.position.z"][0]
    assert r.summary["motor_sign_convention"].startswith("hoist")
    # the elevator keeps the engine's sign, which for R1 raises the car: simulate's torque at rest is the
    # plant FMU's holding torque (the drive's pre-torque), both positive
    from reeve_fmu.studies.verdicts import holding_torque

    e = reeve_fmu.simulate(R1, t_end=0.002)
    assert e.summary["motor_sign_convention"].startswith("engine")
    assert e["motor.torque"][0] == pytest.approx(holding_torque(load_scene(R1), 1000.0, 0.0), rel=1e-9)
    assert e["motor.torque"][0] > 0


def test_crane_simulate_plots_and_writes_the_jib_swing_and_yaw_angles(tmp_path, capsys):
    """results.csv carries the crane plant FMU's derived angles and crane.png shows them with the jib
    angle. At rest the payload hangs under the tip (no swing); while the jib accelerates (a positive slew
    from 2 s, docs/crane.md) the payload lags: the tangential swing goes negative first."""
    from reeve_fmu.core.results import read_csv

    rc = main(["simulate", str(ROOT / "scenes" / "slewing_crane.toml"), "--t-end", "6", "--out", str(tmp_path)])
    assert rc == 0, capsys.readouterr().err
    c = read_csv(tmp_path / "results.csv")
    assert abs(c["payload.swing_radial"][0]) < 1e-9 and abs(c["payload.swing_tangential"][0]) < 1e-9
    swing = c["payload.swing_tangential"]
    k = int(np.argmax(np.abs(swing) > 1e-3))                 # first visible swing (> 0.06 deg)
    assert k > 0 and swing[k] < 0 and c["jib.angular_velocity"][k] > 0
    assert (tmp_path / "crane.png").stat().st_size > 10_000
    assert "![crane.png](crane.png)" in (tmp_path / "report.md").read_text(encoding="utf-8")


def test_plot_lines_keep_every_bucket_extreme():
    """Plot lines are thinned to each run of samples' smallest and largest value (report._envelope):
    a 61 050-sample trip becomes about 3000 points, in time order, that still reach every local extreme of
    the run, so the drawn line covers the same pixels; a short or non-finite line stays whole."""
    from reeve_fmu.studies.report import _envelope

    t = np.arange(61050) * 1e-3
    y = np.sin(7.0 * t) + 0.01 * np.random.default_rng(3).standard_normal(t.size)
    y[12345] = 5.0                                      # a one-sample spike
    tt, yy = _envelope(t, y)
    k = 40                                              # samples per bucket: 61050 // 1500
    assert tt.size == 2 * (t.size // k) + t.size % k == 3062 and np.all(np.diff(tt) > 0)
    for b in range(0, t.size // k, 97):
        seg = y[b * k:(b + 1) * k]
        assert set(yy[2 * b:2 * b + 2]) == {seg.min(), seg.max()}
    assert yy.max() == 5.0 and tt[np.argmax(yy)] == t[12345]
    assert np.array_equal(yy[-(t.size % k):], y[-(t.size % k):])    # the tail, whole
    short = np.arange(5000.0)
    assert _envelope(short, short)[0] is not None and _envelope(short, short)[0].size == 5000
    y[7] = np.nan
    assert _envelope(t, y)[1].size == t.size
