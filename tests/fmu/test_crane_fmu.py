"""Joint inputs of the Plant and the crane plant / crane drive FMUs (scenes/slewing_crane.toml).

Core: a speed input integrates exactly (trapezoid over each step), a torque input is the torque table
with the same values. FMUs: built once by `reeve-fmu build --scene`, fmpy validate clean, static
payload tension = M g, honest state, the centripetal swing angle tan(phi) = w^2 r / g of a steady slew,
solver failures logged and discarded. Every FMU-loading check runs in its own interpreter
(tests/support/crane_jobs.py via run_in_subprocess).
"""
from __future__ import annotations

import math
import sys
from dataclasses import replace

import numpy as np
import pytest

from tests.support import ROOT
from tests.support.checks import check

ROUNDOFF = "round-off, which differs by platform"
EXACT = "exact here; round-off in general"

SCENE = ROOT / "scenes" / "slewing_crane.toml"
JOBS = str(ROOT / "tests" / "support" / "crane_jobs.py")
G, M = 9.81, 2500.0


def job(name, *args, timeout=900.0):
    from reeve_fmu.fmu.runner import run_in_subprocess

    return run_in_subprocess(f"{JOBS}:{name}", *args, timeout=timeout)


# ------------------------------------------------------------------------------------------------
# core: joint inputs
# ------------------------------------------------------------------------------------------------
def test_speed_input_is_integrated_exactly_and_torque_input_equals_the_torque_table():
    from reeve_fmu.components.plant import Plant, with_joint_input
    from reeve_fmu.core.scene import Motion, SceneError, load_scene

    sc = load_scene(SCENE)
    p = Plant(with_joint_input(sc, "jib", "speed"))
    assert p.joint_inputs == ("jib.speed",)
    ws, dt, angle, w_prev = [0.02, 0.05, 0.05, -0.01, 0.0], 0.04, 0.0, 0.0
    for w in ws:
        y = p.step(dt, p.holding_torque(), 0.0, [w])
        angle += 0.5 * (w_prev + w) * dt          # the ramp's exact integral
        w_prev = w
        check('p.output("jib.angular_velocity") - w', p.output("jib.angular_velocity") - w, 1e-15, reason=EXACT)
        check('p.output("jib.angle") - angle', p.output("jib.angle") - angle, 1e-15, reason=ROUNDOFF)
    assert np.isfinite(y).all()
    # torque input = a torque table with the same constant value (same kernel path): identical runs
    tau = 3.0e4
    a = Plant(with_joint_input(sc, "jib", "torque"))
    jib = next(b for b in sc.bodies if b.name == "jib")
    # (0 at t = 0 like the input before its first step: the initial statics holds the jib there)
    table = replace(sc, bodies=tuple(replace(b, motion=Motion(kind="torque", torque=((0.0, 0.0), (1e-12, tau))))
                                     if b is jib else b for b in sc.bodies))
    b = Plant(table)
    for _ in range(20):
        ya = a.step(0.01, 0.0, 0.0, [tau])
        yb = b.step(0.01, 0.0, 0.0)
    assert np.array_equal(ya, yb)
    check('a.output("jib.joint_torque") - tau', a.output("jib.joint_torque") - tau, 1e-11 * np.max(np.abs(tau)))
    assert a.output("jib.angular_velocity") > 0.0
    with pytest.raises(ValueError, match="jib.torque must be finite"):
        a.step(0.01, 0.0, 0.0, [math.nan])
    with pytest.raises(SceneError, match="no body named 'car' on a joint"):
        with_joint_input(sc, "car", "speed")


# ------------------------------------------------------------------------------------------------
# the FMUs
# ------------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    dest = tmp_path_factory.mktemp("crane_fmus")
    r = job("build", str(dest))
    assert r["rc"] == 0
    return {"dir": dest, "problems": r["problems"], "plant": str(dest / "CranePlant.fmu"),
            "drive": str(dest / "CraneDrive.fmu")}


def test_crane_fmus_build_validate_and_declare_units(fmus):
    import zipfile
    from xml.etree import ElementTree as ET

    assert fmus["problems"] == {"CranePlant.fmu": [], "CraneDrive.fmu": []}
    assert (fmus["dir"] / "CranePlant.drive.json").is_file()       # <plant name>.drive.json, as for elevators
    root = ET.fromstring(zipfile.ZipFile(fmus["plant"]).read("modelDescription.xml"))
    v = {sv.get("name"): sv for sv in root.find("ModelVariables")}
    for name in ("motor.torque", "slew.torque", "slew.speed"):
        assert v[name].get("causality") == "input" and v[name].get("description")
    for name in ("payload.position.x", "payload.velocity.z", "payload.swing_radial", "payload.swing_tangential",
                 "payload.yaw", "tip.tension_in", "tip.tension_out", "jib.angle", "jib.angular_velocity",
                 "jib.joint_torque"):
        assert v[name].get("causality") == "output", name
        t = v[name][0]
        assert t.get("declaredType") or t.get("unit"), name
    assert v["slew.input"][0].tag == "Integer" and v["slew.input"].get("variability") == "fixed"


def test_crane_fmu_static_tension_and_honest_state(fmus):
    r = job("static_and_state", fmus["plant"])
    assert r["errors"] == []
    # payload-end rope force at rest = M g, at t = 0 and after 2 s: measured 1.1e-6 N, the statics'
    # round-off (4.5e-11 of M g)
    for row in (r["t0"], r["t2"]):
        check('row[0] - (M * G)', row[0] - (M * G), 1e-5)
    check('r["t2"][1] - r["t0"][1]', r["t2"][1] - r["t0"][1], 1.8e-11)  # the holding torque holds
    assert r["a"] == r["b"] == r["c"]                    # rewind and deserialize: bit-identical


def test_crane_fmu_centripetal_swing_angle(fmus):
    """A steady slew at w: the load hangs outwards at tan(phi) = w^2 r / g (point load on a long
    rope). After a 16 s S-curve ramp the load still swings about that angle in the two modes of the
    rotating frame (about w_p -+ w, w_p = 0.8 rad/s the pendulum frequency); the mean of
    tan(phi) / (w^2 r / g) is fitted together with both sinusoids over the last 9.5 s."""
    from scipy.optimize import curve_fit

    w = 0.2
    r = job("centripetal", fmus["plant"], fmus["drive"], w, 16.0, 26.0)
    t = np.array(r["t"])
    last = t > 16.5
    assert np.allclose(np.array(r["w"])[last], w, rtol=1e-9)
    ratio = np.tan(np.array(r["radial"])[last]) / (w * w * np.array(r["r"])[last] / G)

    def model(t, c, a1, b1, w1, a2, b2, w2):
        return c + a1 * np.cos(w1 * t) + b1 * np.sin(w1 * t) + a2 * np.cos(w2 * t) + b2 * np.sin(w2 * t)
    wp = math.sqrt(G / 15.6)
    p, _ = curve_fit(model, t[last], ratio, p0=[1.0, 0.1, 0.1, wp - w, 0.1, 0.1, wp + w])
    check('np.std(ratio - model(t[last], *p))', np.std(ratio - model(t[last], *p)), 0.00015)  # the fit explains the swing
    # the rope's own mass (0.7 % of the load), the box and the rope leaving the tip sheave at the swing
    # angle are not in the point-mass formula
    check('p[0] - 1.0', p[0] - 1.0, 5e-3)


def test_crane_fmu_solver_failure_is_logged_and_discarded(fmus):
    r = job("solver_failure", fmus["plant"])
    assert r["statuses"][-1] == 2 and all(s == 0 for s in r["statuses"][:-1])
    assert r["after"] >= 2
    text = "\n".join(m for _, m in r["log"])
    assert "(tip -> payload anchor) is shorter than solver.min_span" in text, text[-2000:]
    assert "motor.torque = nan is not finite" in text


def test_crane_build_of_another_scene_is_named_after_it(tmp_path):
    """The elevator's naming rule for cranes: a crane scene other than scenes/slewing_crane.toml as it
    is (here the reference changed by --set) builds Plant_<scene name>.fmu with its own entry module and
    <name>.drive.json; CranePlant.fmu only for the reference scene or an explicit --name (announced)."""
    import json
    import subprocess
    import zipfile

    cmd = [sys.executable, "-m", "reeve_fmu.cli", "build", "--scene", str(SCENE), "--dest", str(tmp_path),
           "--set", 'scene.name="jib_b"']
    p = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stdout + p.stderr
    assert sorted(f.name for f in tmp_path.glob("*.fmu")) == ["CraneDrive.fmu", "Plant_jib_b.fmu"]
    assert "hoist.holding_torque" in json.loads((tmp_path / "Plant_jib_b.drive.json").read_text())["drive"]
    with zipfile.ZipFile(tmp_path / "Plant_jib_b.fmu") as zf:
        assert 'modelName="Plant_jib_b"' in zf.read("modelDescription.xml").decode()
        assert zf.read("resources/slavemodule.txt").decode() == "reeve_crane_plant_jib_b_slave"
    q = subprocess.run(cmd + ["--name", "CranePlant"], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert q.returncode == 0, q.stdout + q.stderr
    assert "replaces the reference plant FMU (scene slewing_crane.toml) with jib_b" in q.stdout
    assert (tmp_path / "CranePlant.fmu").is_file() and (tmp_path / "CranePlant.drive.json").is_file()
