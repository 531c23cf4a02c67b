"""Physically wrong input gets a clear answer (core/plausibility.py, cli.run_command), the statics
starts from singular configurations, and a run stopped by an event keeps its results."""
from dataclasses import replace
import json

import numpy as np
import pytest

from reeve_fmu.cli import main, real_time
from reeve_fmu.core.model import build_model
from reeve_fmu.core.plausibility import PlausibilityError, check_or_raise, check_scene
from reeve_fmu.core.results import read_csv
from reeve_fmu.core.scene import SceneError, load_scene, loads_scene
from reeve_fmu.core.solver import Simulator
from tests.support import ROOT
from tests.support.checks import check, check_png

ELEVATOR = (ROOT / "scenes" / "elevator_2to1.toml").read_text(encoding="utf-8")
SHIPPED = sorted((ROOT / "scenes").rglob("*.toml"))


def elevator(old, new):
    assert old in ELEVATOR
    return loads_scene(ELEVATOR.replace(old, new), "elevator.toml")


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.name)
def test_shipped_scenes_are_plausible(path):
    assert check_scene(load_scene(path)) == []


@pytest.mark.parametrize("EA, unit", [("4.5", "MN"), ("4.5e3", "kN")])
def test_EA_unit_slip_is_an_error_naming_key_and_unit(EA, unit):
    sc = elevator("EA = 2.9e6", f"EA = {EA}")
    with pytest.raises(PlausibilityError) as exc:
        check_or_raise(sc)
    msg = str(exc.value)
    assert "elevator.toml: [ropes[0].EA]" in msg and f"given in {unit}?" in msg and "static strain" in msg


def test_EA_strain_between_2_and_20_percent_warns():
    # estimated static tension ~2.1 kN per rope: EA = 50 kN gives ~4 % strain
    (w,) = check_or_raise(elevator("EA = 2.9e6", "EA = 5e4"))
    assert "[ropes[0].EA]" in w and "static strain of about 4" in w


def test_EA_a_million_times_too_large_warns():
    (w,) = check_or_raise(elevator("EA = 2.9e6", "EA = 2.9e12"))
    assert "[ropes[0].EA]" in w and "1e6 times too large?" in w


def test_crossing_wrap_names_the_sheave_and_the_sense_that_does_not_cross():
    sc = elevator('{ sheave = "car_sheave", wrap = "ccw" }', '{ sheave = "car_sheave", wrap = "cw" }')
    (w,) = check_or_raise(sc)
    assert "[ropes[0].route[1].wrap]" in w and "cross" in w
    assert "sheave 'car_sheave' with wrap = 'ccw' would not cross" in w


def test_wrap_of_more_than_half_a_turn_warns():
    """3D: the lead-in span comes from 3 m aside, so the wrong sense does not make the spans cross;
    it wraps the rope 287 deg round the sheave (and pulls the hook sideways)."""
    txt = """
[scene]
model = "spatial"
[[bodies]]
name = "hook"
mass = 1000.0
position = [1.0, 0.0, 0.0]
free = ["x", "y", "z"]
[[sheaves]]
name = "head"
center = [0.0, 0.0, 10.0]
radius = 0.5
[[ropes]]
name = "rope"
EA = 2e7
rhoA = 1.0
route = [{ anchor = "ground", at = [-5.0, 3.0, 10.5] }, { sheave = "head", wrap = "%s" },
         { anchor = "hook", at = [-0.5, 0.0, 0.0] }]
"""
    assert check_scene(loads_scene(txt % "cw", "h.toml")) == []
    (w,) = check_or_raise(loads_scene(txt % "ccw", "h.toml"))
    assert "[ropes[0].route[1].wrap]" in w and "wraps 287 deg" in w and "wrap = 'cw' gives 90 deg" in w


def test_gravity_in_mm_per_s2_and_small_sheaves_and_masses_warn():
    found = check_scene(elevator("gravity = [0.0, 0.0, -9.81]", "gravity = [0.0, 0.0, -9810.0]"))
    assert [f.key for f in found] == ["ropes[0].EA", "scene.gravity"]      # error first
    assert "or scene.gravity: |g| = 9810" in found[0].message and "mm/s^2" in found[1].message
    (w,) = check_or_raise(elevator("gravity = [0.0, 0.0, -9.81]", "gravity = [0.0, 0.0, -9.0]"))
    assert "[scene.gravity] |g| = 9 m/s^2 is far from" in w
    warns = check_or_raise(elevator("radius = 0.16", "radius = 0.016"))
    assert any("[sheaves[0].radius]" in w and "EN 81-50 asks D/d >= 40" in w for w in warns)
    warns = check_or_raise(elevator("mass = 1750.0", "mass = 1.75"))
    assert any("[bodies[1].mass]" in w and "in kg" in w for w in warns)


def test_span_shorter_than_min_span_is_an_error_at_build():
    sc = elevator("newton_tol = 1e-4", "newton_tol = 1e-4\nmin_span = 4.0")
    with pytest.raises(PlausibilityError, match=r"\[ropes\[0\]\.route\[\d\]\] rope 'hoist' span \d .* shorter "
                                                r"than solver.min_span = 4 m"):
        check_or_raise(sc)


@pytest.mark.parametrize("model", ["planar", "spatial"])
def test_statics_singular_first_step_converges(model):
    """Interior nodes of unloaded spans have no transverse stiffness at the start (a ~1e16 condition
    number): with 3 and 4 linear elements per span and the hook 1 m off its place, the statics
    converges, and the rope force at the hook is its weight (9810 N)."""
    sc = load_scene(ROOT / "tests" / "scenes" / "drum_hoist.toml")
    err = []
    for n in (3, 4):
        for dz in (-1.0, 1.0):
            s2 = replace(sc, model=model, ropes=tuple(replace(r, elements_per_span=n) for r in sc.ropes),
                         bodies=tuple(replace(b, position=(2.0, 0.0, dz)) for b in sc.bodies))
            sim = Simulator(build_model(s2))
            y = dict(zip(sim.model.output_names, sim.outputs(sim.initial_state())))
            err.append(y["rope.tension_end"] - 1000.0 * 9.81)
    check("rope force at the hook - its weight [N]", err, 5e-7,
          reason="round-off of a statics started at a ~1e16 condition number: it differs by model and platform")


def test_statics_failure_names_the_body_and_the_force():
    sc = loads_scene((ROOT / "scenes" / "hanging_rope.toml").read_text(encoding="utf-8") + (
        '\n[[bodies]]\nname = "loose"\nmass = 10.0\nposition = [5.0, 0.0, 0.0]\nfree = ["z"]\n'), "loose.toml")
    with pytest.raises(Exception, match=r"unbalanced force -98.1 N on body 'loose' \(loose.z\)"):
        Simulator(build_model(sc)).initial_state()


def test_unknown_body_lists_the_bodies():
    with pytest.raises(SceneError, match=r"\[buffers\[0\]\.body\] unknown body 'cab'; bodies: car, counterweight"):
        loads_scene(ELEVATOR + '\n[[buffers]]\nname = "b"\nbody = "cab"\nposition = 0.0\nstiffness = 1e5\n')


def test_real_time_factor_text():
    assert real_time(1.0, 9.1) == "0.11x real time"
    assert real_time(10.0, 4.0) == "2.5x real time"
    assert real_time(1364.0, 1.0) == "1364x real time"


# ------------------------------------------------------------------------------- command line
STOP_SCENE = (ROOT / "tests" / "scenes" / "drum_hoist.toml").read_text(encoding="utf-8").replace(
    "position = [2.0, 0.0, 0.0]", "position = [2.0, 0.0, 27.0]")   # 3 m below the head sheave


def test_run_stopped_by_an_event_keeps_its_results(tmp_path, capsys):
    """The drum reels in 5 m but the hook hangs 3 m below the head sheave: the span vanishes at
    t ~ 3.6 s. Exit 3, and the CSV, plot and summary hold everything up to the event."""
    scene = tmp_path / "stop.toml"
    scene.write_text(STOP_SCENE, encoding="utf-8")
    rc = main(["simulate", str(scene), "--t-end", "8", "--dt", "0.01", "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert rc == 3
    assert "run stopped by an event" in err and "vanishing span" in err and "Traceback" not in err
    summ = json.loads((tmp_path / "out" / "summary.json").read_text(encoding="utf-8"))
    ev = summ["event"]
    assert 2.0 < ev["time"] < 8.0 and "vanishing span" in ev["cause"] and summ["exit_code"] == 3
    cols = read_csv(tmp_path / "out" / "results.csv")
    assert cols["time"][-1] == pytest.approx(ev["time"], abs=1e-9)
    assert cols["time"][-2] > ev["time"] - 0.01 - 1e-9          # every sample up to the event
    assert np.all(np.isfinite(cols["hook.position"]))
    check_png(tmp_path / "out" / "results.png")


def test_physically_wrong_scene_exits_2_with_one_line(tmp_path, capsys):
    scene = tmp_path / "ea.toml"
    scene.write_text(ELEVATOR.replace("EA = 2.9e6", "EA = 4.5"), encoding="utf-8")
    rc = main(["simulate", str(scene), "--out", str(tmp_path)])
    err = capsys.readouterr().err
    assert rc == 2 and "[ropes[0].EA]" in err and "Traceback" not in err


def test_internal_error_is_one_line_and_debug_shows_the_traceback(tmp_path, capsys, monkeypatch):
    import reeve_fmu.core.model as model

    def broken(scene):
        return None + 1.0
    monkeypatch.setattr(model, "build_model", broken)
    args = ["simulate", str(ROOT / "scenes" / "hanging_rope.toml"), "--out", str(tmp_path)]
    assert main(args) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "internal error: TypeError" in err and "--debug" in err
    assert main(args + ["--debug"]) == 1
    assert "Traceback (most recent call last)" in capsys.readouterr().err


ONE_FALL = """[scene]
name = "crane_one_fall"
model = "spatial"
gravity = [0.0, 0.0, -9.81]
[initial]
statics = "rope-length"
[[bodies]]
name = "block"
mass = 15500.0
inertia = [500.0, 500.0, 300.0]
position = [0.0, 0.0, -5.5]
free = ["x", "y", "z", "rotation"]
[[sheaves]]
name = "drum"
kind = "drum"
center = [-20.0, 0.0, -49.0]
radius = 0.3
stored = 100.0
[[sheaves]]
name = "tip"
center = [-0.25, 0.0, 0.0]
radius = 0.25
[[ropes]]
name = "hoist"
EA = 2.28e7
rhoA = 2.4
length = 158.0
torsion = { law = "torque-factor", diameter = 0.022, k0 = 0.0, GJ0 = 0.0 }
route = [
  { sheave = "drum", wrap = "cw" },
  { sheave = "tip", wrap = "cw" },
  { anchor = "block", at = [0.0, 0.0, 0.5] },
]
[drive]
kind = "speed"
sheave = "drum"
[crane]
block = "block"
height_min = 2.0
height_max = 40.0
heights = 20
"""


def test_crane_without_yaw_stiffness_is_explained():
    """One fall at the block's centre and the torque-factor law with GJ0 = 0: nothing turns the block
    back; with GJ0 > 0 the same crane has an equilibrium."""
    from reeve_fmu.studies.crane import CraneError, build_crane, sweep
    with pytest.raises(CraneError, match="yaw has no stiffness .* law = 'torque-factor' .* yaw is undetermined"):
        sweep(build_crane(loads_scene(ONE_FALL, "one_fall.toml")), np.linspace(2.0, 10.0, 3))
    res = sweep(build_crane(loads_scene(ONE_FALL.replace("GJ0 = 0.0", "GJ0 = 2000.0"), "one_fall.toml")),
                np.linspace(2.0, 10.0, 3))
    assert np.all(np.isfinite(res.columns["block.yaw"]))


def test_plant_keeps_the_warnings_for_the_fmu_log():
    """The plant FMU logs Plant.warnings at initialization (fmus/reeve_plant_slave.py)."""
    from reeve_fmu.components.plant import Plant
    plant = Plant(elevator("gravity = [0.0, 0.0, -9.81]", "gravity = [0.0, 0.0, -9.5]"))
    assert any("[scene.gravity] |g| = 9.5 m/s^2" in w for w in plant.warnings)
    with pytest.raises(PlausibilityError, match=r"\[ropes\[0\]\.EA\]"):
        Plant(elevator("EA = 2.9e6", "EA = 4.5"))
