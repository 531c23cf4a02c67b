"""No verdict on an impossible configuration: bodies on the wrong side of their sheaves, compressed ropes in
the statics, brakes and drives that cannot hold the car are errors naming the key (or FAIL verdicts
saying why); the EN 81-20 brake and unintended-movement verdicts against their kinematics."""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from reeve_fmu.core.plausibility import PlausibilityError, check_or_raise, check_statics
from reeve_fmu.core.scene import SceneError, load_scene
from reeve_fmu.studies import verdicts as vd
from reeve_fmu.studies.overrides import scene_with
from tests.support import ROOT

R1 = ROOT / "scenes" / "elevator_2to1.toml"


def _errors(scene):
    with pytest.raises(PlausibilityError) as info:
        check_or_raise(scene)
    return str(info.value)


@pytest.mark.parametrize("key, value, body", [
    ("bodies.counterweight.position", [0.32, 0.0, 45.0], "bodies[1].position"),   # above the traction sheave
    ("bodies.car.position", [0.0, 0.0, 41.0], "bodies[0].position"),              # car sheave above the hitch
])
def test_a_body_above_the_sheaves_that_carry_it_is_an_error(key, value, body):
    sc, _ = scene_with(R1, {key: value})
    text = _errors(sc)
    assert f"[{body}]" in text and "compressed rope" in text, text


def test_no_shipped_scene_has_a_body_its_ropes_cannot_lift():
    for path in sorted((ROOT / "scenes").rglob("*.toml")) + sorted((ROOT / "tests" / "scenes").glob("*.toml")):
        check_or_raise(load_scene(path))           # raises on any error finding


def test_a_sheave_radius_in_mm_names_the_sheave():
    sc, _ = scene_with(R1, {"sheaves.traction.radius": 160.0})
    text = _errors(sc)
    assert "[sheaves[1].radius]" in text and "'traction'" in text and "given in mm?" in text, text


def test_statics_with_a_compressed_rope_names_the_rope():
    sc = load_scene(R1)
    ok = {"traction.tension_in": 1.0e4, "traction.tension_out": 8.0e3, "hoist.tension_end": 8.0e3}
    assert check_statics(sc, ok) == []
    bad = dict(ok, **{"traction.tension_out": -9.6e3, "hoist.tension_end": -9.5e3})
    found = check_statics(sc, bad, "with 1000 kg at 0 m")
    assert [f.key for f in found] == ["ropes[0]"]           # one finding per rope, at its most compressed force
    assert "-9600 N at traction.tension_out" in found[0].message and "with 1000 kg at 0 m" in found[0].message


def _cli(argv, capsys):
    from reeve_fmu.cli import main

    rc = main(argv)
    return rc, capsys.readouterr()


def test_simulate_refuses_the_counterweight_above_its_sheave(tmp_path, capsys):
    rc, out = _cli(["simulate", str(R1), "--set", "bodies.counterweight.position=[0.32, 0, 45.0]",
                    "--t-end", "0.01", "--out", str(tmp_path)], capsys)
    assert rc == 2 and "[bodies[1].position]" in out.err, out.err
    assert "PASS" not in out.out + out.err and not (tmp_path / "summary.json").exists()


def test_a_rope_too_short_for_the_statics_names_its_length(tmp_path, capsys):
    rc, out = _cli(["simulate", str(R1), "--set", 'initial.statics="rope-length"', "--set", "ropes.hoist.length=5",
                    "--t-end", "0.01", "--out", str(tmp_path)], capsys)
    assert rc == 2 and "ropes[0].length = 5 m" in out.err and "its route at the given positions is" in out.err, out.err


def test_holding_torque_does_not_depend_on_the_brake():
    """The pre-torque comes from the statics with the brake's capacity raised: a weak brake (which
    slips at its capacity) does not change it."""
    strong = vd.holding_torque(load_scene(R1), 1000.0, 0.0)
    weak, _ = scene_with(R1, {"brake.torque": 100.0})
    assert vd.holding_torque(weak, 1000.0, 0.0) == pytest.approx(strong, rel=1e-9)


@pytest.mark.parametrize("z, car_span, cw_span", [(0.0, 40.0, 3.0), (39.0, 1.0, 42.0)])
def test_holding_torque_is_the_lever_rule_with_the_rope_weights(z, car_span, cw_span):
    """R1 (2:1, R = 0.16 m): R (T_in - T_out) with T = m g / 2 per side plus the weight of the vertical
    span between the traction sheave and each pulley (6 ropes x 0.26 kg/m). Measured 1.2e-4 and
    1.6e-4 relative (hitch springs and wrap rope the rule leaves out)."""
    g, w = 9.81, 6 * 0.26 * 9.81
    expected = 0.16 * ((2300.0 - 1750.0) * g / 2 + w * (car_span - cw_span))
    assert vd.holding_torque(load_scene(R1), 1000.0, z) == pytest.approx(expected, rel=1e-3)


def test_a_brake_below_the_holding_torque_is_an_error_at_its_boundary():
    from reeve_fmu.studies.trip import trip_case

    hold = vd.holding_torque(load_scene(R1), 1000.0, 0.0)
    with pytest.raises(SceneError, match=r"\[brake.torque\] = .* cannot hold the car with 1000 kg at 0 m: that needs "
                                         rf"{hold:.1f} N·m"):
        trip_case(R1, sets={"brake.torque": hold - 1.0})
    case = trip_case(R1, sets={"brake.torque": hold + 1.0})      # holds the trip's load, not 125 %
    assert case.holding_torques[0.0] == pytest.approx(hold, rel=1e-12)
    st = {v.check: v.status for v in vd.brake_verdicts(case.scene)}
    assert st["EN 81-20 brake stops and holds the car (125 % rated load)"] == "FAIL"
    assert st["EN 81-20 brake, one circuit of 2 (rated load)"] == "FAIL"


def test_one_brake_circuit_holds_the_rated_load_exactly_above_its_holding_torque():
    hold = max(abs(vd.holding_torque(load_scene(R1), 1000.0, z)) for z in (0.0, 39.0))
    for T, status in ((2 * hold - 2.0, "FAIL"), (2 * hold + 2.0, "PASS")):
        sc, _ = scene_with(R1, {"brake.torque": T})
        v = next(v for v in vd.brake_verdicts(sc) if "one circuit" in v.check)
        assert v.status == status, v.line()


def test_a_drive_that_cannot_hold_the_car_names_torque_max():
    from reeve_fmu.studies.trip import trip_case

    with pytest.raises(ValueError, match=r"\[torque.max\] = 300 N·m \(--set torque.max\) cannot hold the car"):
        trip_case(R1, sets={"torque.max": 300.0})


def test_unintended_movement_distance_is_the_rigid_kinematics():
    """Free acceleration a0 = |hold| R / (J roping) to the detection point, a0 on for the engage time,
    then the brake's deceleration (T - |hold|) R / (J roping): the closed form."""
    bc = {"radius": 0.5, "roping": 2.0, "rated_load": 1.0, "ends": (0.0, 10.0),
          "hold": {0.0: [-40.0, -20.0], 1.0: [80.0, 60.0]}, "inertia": {0.0: 10.0, 1.0: 10.0}}
    scene = SimpleNamespace(brake=SimpleNamespace(engage_time=0.1))
    a0 = 80.0 * 0.5 / (10.0 * 2.0)                    # 2 m/s², the larger imbalance
    dec = (200.0 - 80.0) * 0.5 / (10.0 * 2.0)         # 3 m/s²
    v0 = math.sqrt(2 * a0 * vd.UCM_DETECTION)
    v1 = v0 + a0 * 0.1
    d = vd.UCM_DETECTION + v0 * 0.1 + 0.5 * a0 * 0.01 + v1 ** 2 / (2 * dec)
    v = vd._ucm_verdict(scene, bc, 200.0)
    assert v.value == pytest.approx(d, rel=1e-12) and v.status == "PASS" and "1 kg at 0 m" in v.note
    assert vd._ucm_verdict(scene, bc, 79.0).status == "FAIL"          # the brake cannot stop it: inf
    assert vd._ucm_verdict(scene, bc, 79.0).value == math.inf


@pytest.mark.parametrize("value", [-1.276, math.inf, math.nan, 0.5])
def test_a_traction_ratio_that_is_no_ratio_never_passes(value):
    v = vd._ratio_verdict("EN 81-50 car loading", value, 1.858, lambda r: r <= 1.858, "src")
    assert v.status == "FAIL" and "not positive" in v.note


def test_a_record_with_a_compressed_rope_passes_nothing():
    t = np.linspace(0.0, 1.0, 11)
    good = {"hoist.tension_start": np.full(11, 1e4), "pit.force": 0 * t}
    assert [v.status for v in vd._not_assessed(vd.generic_verdicts(t, good), t, good)] == ["PASS", "PASS"]
    bad = dict(good, **{"hoist.tension_start": np.linspace(1e4, -50.0, 11)})
    vs = vd._not_assessed(vd.generic_verdicts(t, bad) + vd.ride_verdicts({"max_jerk_m_s3": 0.5}), t, bad)
    assert [v.status for v in vs] == ["FAIL", "INFO", "INFO"]
    assert "not assessed: rope force -50 N at hoist.tension_start, t = 1.000 s" in vs[1].note
    assert vd.worst(vs) == "FAIL"
