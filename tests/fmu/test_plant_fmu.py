"""The plant and electric-drive FMUs: build, modelDescription, validation, honest state, errors.

Both FMUs are built once per session with the CLI (`reeve-fmu build --dest ...`); every check that
loads an FMU runs in its own fresh interpreter (tests/support/cosim_jobs.py via run_in_subprocess).
The first FMU run after a change of the package sources compiles the numba kernels (~60 s, cached
under ~/.cache/reeve_fmu per source hash).
"""
from __future__ import annotations

import subprocess
import sys
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

import pytest

from reeve_fmu.fmu.runner import run_in_subprocess
from tests.support import ROOT
from tests.support.checks import check

SPREAD = "the cases' errors differ by more than 10x: one bound for all"

JOBS = str(ROOT / "tests" / "support" / "cosim_jobs.py")


def job(name, *args, timeout=300.0):
    return run_in_subprocess(f"{JOBS}:{name}", *args, timeout=timeout)


def _md(fmu):
    with zipfile.ZipFile(fmu) as zf:
        return ET.fromstring(zf.read("modelDescription.xml")), zf.namelist()


def _vars(root):
    out = {}
    for i, sv in enumerate(root.find("ModelVariables"), start=1):
        typ = sv[0]
        out[sv.get("name")] = dict(sv.attrib, index=i, type=typ.tag, **{f"t_{k}": v for k, v in typ.attrib.items()})
    return out


# ------------------------------------------------------------------------------------------------
# build, validation, modelDescription
# ------------------------------------------------------------------------------------------------
def test_build_writes_both_fmus_and_fmpy_validate_finds_no_problems(fmus):
    assert "ReevingPlant.fmu" in fmus["build_log"] and "ElectricDrive.fmu" in fmus["build_log"]
    for key in ("plant", "drive"):
        p = subprocess.run([sys.executable, "-m", "fmpy", "validate", fmus[key]],
                           capture_output=True, text=True, timeout=600)
        assert p.returncode == 0, p.stdout + p.stderr
        assert "No problems found" in p.stdout


def test_plant_model_description(fmus):
    root, names = _md(fmus["plant"])
    assert root.get("modelName") == "ReevingPlant"
    cs = root.find("CoSimulation")
    assert cs.get("modelIdentifier") == "ReevingPlant"
    assert cs.get("canGetAndSetFMUstate") == "true" and cs.get("canSerializeFMUstate") == "true"
    assert cs.get("canHandleVariableCommunicationStepSize") == "true"
    assert cs.get("canInterpolateInputs") == "false"
    # the FMU carries the package (vendored + bootstrap shim), its scene and its config
    assert "resources/scene.toml" in names and "resources/reeve_plant.json" in names
    assert "resources/reeve_fmu_vendor/reeve_fmu/components/plant.py" in names
    assert "resources/reeve_fmu.py" in names and "resources/reeve_plant_slave.py" in names
    assert (ROOT / "scenes" / "elevator_2to1.toml").read_bytes() == \
        zipfile.ZipFile(fmus["plant"]).read("resources/scene.toml")
    v = _vars(root)
    units = {u.get("name") for u in root.find("UnitDefinitions")}
    for name, d in v.items():
        if d["type"] == "Real":
            assert d.get("t_unit") in units, f"{name} has no defined unit"
            assert d.get("description"), name
        else:
            assert d["variability"] in ("discrete", "fixed", "tunable"), name
    assert v["motor.torque"]["causality"] == "input" and v["motor.torque"]["t_unit"] == "N.m"
    assert v["brake.command"]["causality"] == "input" and v["brake.command"]["variability"] == "discrete"
    params = {"car.load": ("kg", 1000.0), "rope.EA": ("N", 2.9e6), "rope.damping": ("s", 2e-3),
              "brake.static_torque": ("N.m", 1400.0), "motor.inertia": ("kg.m2", 2.5)}
    for name, (unit, start) in params.items():
        d = v[name]
        assert (d["causality"], d["variability"], d["initial"]) == ("parameter", "fixed", "exact"), name
        assert d["t_unit"] == unit and float(d["t_start"]) == start, name
    cli_names = ["car.position", "car.velocity", "car.acceleration", "counterweight.position",
                 "traction.tension_in", "traction.tension_out", "traction.traction_ratio",
                 "car_sheave.tension_in", "cw_sheave.tension_out", "hoist.tension_start", "hoist.tension_end",
                 "motor.angle", "motor.speed", "brake.torque", "brake.engaged"]
    outputs = {n for n, d in v.items() if d["causality"] == "output"}
    assert set(cli_names) <= outputs
    for n in outputs:
        assert v[n]["initial"] == "calculated", n
    deps = {}
    for u in root.find("ModelStructure").find("Outputs"):
        name = [n for n, d in v.items() if d["index"] == int(u.get("index"))][0]
        deps[name] = u.get("dependencies")
    assert set(deps) == outputs
    torque_idx = str(v["motor.torque"]["index"])
    for n in outputs:
        expect = torque_idx if (n.endswith(".acceleration") or n.endswith("traction_ratio")
                                or (n.split(".")[1] in ("tension_in", "tension_out"))) else ""
        assert deps[n] == expect, (n, deps[n])
    for n in ("car.position", "car.velocity", "motor.speed", "motor.angle"):
        assert deps[n] == ""                                    # no feed-through torque -> speed/position
    assert v["motor.speed"]["t_derivative"] == str(v["motor.angle"]["index"])
    assert v["car.velocity"]["t_derivative"] == str(v["car.position"]["index"])


def test_drive_model_description(fmus):
    root, names = _md(fmus["drive"])
    assert root.get("modelName") == "ElectricDrive"
    assert "resources/reeve_drive_slave.py" in names
    v = _vars(root)
    assert {n for n, d in v.items() if d["causality"] == "input"} == {"motor.speed", "motor.angle"}
    assert v["motor.speed"]["t_unit"] == "rad/s" and v["motor.angle"]["t_unit"] == "rad"
    assert v["motor.torque"]["causality"] == "output" and v["motor.torque"]["t_unit"] == "N.m"
    assert v["brake.command"]["causality"] == "output" and v["brake.command"]["variability"] == "discrete"
    for p in ("trip.v_max", "trip.a_max", "trip.jerk", "landing[1]", "landing[2]", "pretorque[1]",
              "pretorque[2]", "drive.level", "trip.moves"):
        assert v[p]["causality"] == "parameter" and v[p]["variability"] == "fixed", p
    assert v["drive.level"]["type"] == "Integer" and v["drive.level"]["t_start"] == "1"
    assert float(v["trip.v_max"]["t_start"]) == 1.6 and float(v["landing[2]"]["t_start"]) == 39.0
    for u in root.find("ModelStructure").find("Outputs"):
        assert u.get("dependencies") == ""                      # the drive samples at the step start


def test_plant_fmu_names_follow_one_convention(tmp_path):
    """build, demo and the SSP: ReevingPlant (CranePlant for a crane) only for the reference scene file
    as it is (or by explicit name), Plant_<scene name> for any other scene and for a scene changed by --set."""
    from reeve_fmu.core.scene import load_scene
    from reeve_fmu.demo import plant_fmu_name

    r1, r2 = ROOT / "scenes" / "elevator_2to1.toml", ROOT / "scenes" / "elevator_1to1_highrise.toml"
    assert plant_fmu_name(r1, load_scene(r1)) == "ReevingPlant"
    assert plant_fmu_name(r2, load_scene(r2)) == "Plant_elevator_1to1_highrise"
    changed = tmp_path / "scene.toml"                  # the demo writes a --set scene there
    changed.write_text(r1.read_text(encoding="utf-8"), encoding="utf-8")
    assert plant_fmu_name(changed, load_scene(changed)) == "Plant_elevator_2to1"
    assert plant_fmu_name(r2, load_scene(r2), "ReevingPlant") == "ReevingPlant"     # explicit
    crane = ROOT / "scenes" / "slewing_crane.toml"     # the same rule for the crane plant
    assert plant_fmu_name(crane, load_scene(crane)) == "CranePlant"
    copy = tmp_path / "jib.toml"
    copy.write_text(crane.read_text(encoding="utf-8"), encoding="utf-8")
    assert plant_fmu_name(copy, load_scene(copy)) == "Plant_slewing_crane"
    assert plant_fmu_name(copy, load_scene(copy), "CranePlant") == "CranePlant"


def test_build_with_scene_is_named_after_the_scene(tmp_path):
    """--scene: another scene under its own name (the reference FMU is not touched); the entry module
    gets a unique name."""
    p = subprocess.run([sys.executable, "-m", "reeve_fmu.cli", "build", "--dest", str(tmp_path),
                        "--scene", str(ROOT / "scenes" / "elevator_1to1_highrise.toml")],
                       cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stdout + p.stderr
    fmu = tmp_path / "Plant_elevator_1to1_highrise.fmu"
    assert not (tmp_path / "ReevingPlant.fmu").exists()
    assert (tmp_path / "Plant_elevator_1to1_highrise.drive.json").is_file()
    root, names = _md(fmu)
    assert root.get("modelName") == "Plant_elevator_1to1_highrise"
    assert "resources/reeve_plant_plant_elevator_1to1_highrise_slave.py" in names
    with zipfile.ZipFile(fmu) as zf:
        assert zf.read("resources/slavemodule.txt").decode() == "reeve_plant_plant_elevator_1to1_highrise_slave"
    v = _vars(root)
    assert float(v["car.load"]["t_start"]) == 1600.0            # R2 rated load
    q = subprocess.run([sys.executable, "-m", "fmpy", "validate", str(fmu)], capture_output=True, text=True,
                       timeout=600)
    assert q.returncode == 0, q.stdout
    bad = subprocess.run([sys.executable, "-m", "reeve_fmu.cli", "build", "--dest", str(tmp_path),
                          "--name", "not a name"], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert bad.returncode == 2 and "valid identifier" in bad.stderr


# ------------------------------------------------------------------------------------------------
# physics declared honestly (no FMU needed)
# ------------------------------------------------------------------------------------------------
def test_declared_dependencies_match_the_plant():
    """An output has direct feed-through from motor.torque iff the effect of a torque change over a
    step of length dt tends to a non-zero limit as dt -> 0 (1e-7 s vs 1e-8 s: the same value);
    without feed-through the effect scales with dt (10x smaller)."""
    from reeve_fmu.components.plant import make_plant
    from reeve_fmu.fmu.cosim import plant_output_specs

    plant = make_plant(ROOT / "scenes" / "elevator_2to1.toml")
    specs = {s["name"]: s for s in plant_output_specs(plant.output_names, ["car_sheave", "traction", "cw_sheave"])}
    for k in range(150):                                         # brake open, car moving
        plant.step(1e-3, 700.0, 1.0 if k > 20 else 0.0)
    s0 = plant.get_state()

    def delta(dt):
        plant.set_state(s0)
        a = plant.step(dt, 700.0, 1.0).copy()
        plant.set_state(s0)
        b = plant.step(dt, 1700.0, 1.0).copy()
        return b - a

    d7, d8 = delta(1e-7), delta(1e-8)
    n_dep = 0
    for i, name in enumerate(plant.output_names):
        if name == "motor.torque":
            continue
        if specs[name]["depends"]:
            n_dep += 1
            assert abs(d8[i]) > 1e-6 and 0.9 < d8[i] / d7[i] < 1.1, (name, d7[i], d8[i])
        else:
            check('d8[i]', d8[i], 0.2 * abs(d7[i]) + 1e-12, reason=SPREAD)
    assert n_dep == 9          # 2 accelerations, 3 sheaves x 2 tensions, the traction ratio


# ------------------------------------------------------------------------------------------------
# honest FMU state (each FMU in its own process)
# ------------------------------------------------------------------------------------------------
def test_plant_rewind_is_bit_identical(fmus):
    r = job("plant_rewind", fmus["plant"])
    assert r["errors"] == []
    assert str(Path.home() / ".cache" / "reeve_fmu") in r["pkg_file"] or "reeve_fmu_vendor" not in r["pkg_file"]
    assert r["a"] == r["b"] == r["c"]                             # exact float equality, 120 steps
    assert r["restored"] == r["snap_out"]
    assert r["a"][-1][0] != r["snap_out"][0]                      # the car moved after the snapshot
    assert abs(r["first"][0]) < 1e-9 and r["first"][8] > 400.0    # at rest: the brake holds the car


def test_plant_serialize_to_new_instance_and_new_process(fmus):
    src = job("plant_serialize_source", fmus["plant"])
    assert src["errors"] == [] and src["same_proc"]["errors"] == []   # (errors; a stamp warning is allowed)
    assert src["same_proc"]["cont"] == src["ref"]
    assert src["same_proc"]["load"] == 1000.0                     # fixed parameters come with the state
    dst = job("plant_serialize_target", fmus["plant"], src["blob"], src["t"])
    assert dst["errors"] == []
    assert dst["cont"] == src["ref"]


@pytest.mark.parametrize("level", [1, 2])
def test_drive_state_rewind_and_serialize(fmus, level):
    r = job("drive_state", fmus["drive"], level)
    assert r["errors"] == []
    assert r["a"] == r["b"] == r["c"]
    assert r["level_restored"] == level
    assert any(row[1] == 1.0 for row in r["a"])                   # brake open: in the run phase
    if level == 2:
        assert any(abs(row[5]) > 1.0 for row in r["a"])           # q current flows
    dst = job("drive_state_target", fmus["drive"], r["blob"], r["t"])
    assert dst["errors"] == [] and dst["c"] == r["a"]


# ------------------------------------------------------------------------------------------------
# errors reach the master
# ------------------------------------------------------------------------------------------------
def test_plant_errors_are_logged_and_discarded(fmus):
    r = job("plant_errors", fmus["plant"])
    nan = "\n".join(m for s, m in r["nan_msgs"] if s == 3)
    assert r["nan_step"] == 2 and "motor.torque = nan is not finite" in nan
    assert r["after_nan"] == 0
    crash = "\n".join(m for s, m in r["crash_msgs"] if s == 3)
    assert r["crash_step"] == 2                                   # fmi2Discard, not a crash
    assert "Traceback (most recent call last)" in crash and "SolverError" in crash
    assert "minimum material length" in crash or "did not converge" in crash
    assert r["after_crash"] == r["before_crash"]                  # outputs of the last good step
    assert r["dirty_step"] == 2 and any("previous step raised" in m for _, m in r["dirty_msgs"])
    assert r["after_restore"] == 0
    assert r["bad_dt"] == 2
    assert r["brake_out_of_range_step"] == 2
    assert "brake.command = 2.0 is outside [0.0, 1.0]" in "\n".join(m for _, m in r["brake_msgs"])
    assert r["final"] == 0


def test_plant_reset_after_errors_reproduces_a_clean_run(fmus):
    """fmi2Reset brings the real plant FMU back: after a normal run, and from the error state left by a
    NaN torque and a solver failure (with another car.load), reset + re-initialization reproduce the
    fresh instance's first 80 steps bit for bit, and the parameter is back at its default."""
    r = job("plant_reset", fmus["plant"])
    errs = "\n".join(m for s, m in r["error_msgs"] if s == 3)
    assert (r["nan_step"], r["crash_step"], r["refused_step"]) == (2, 2, 2)
    assert "motor.torque = nan is not finite" in errs and "SolverError" in errs
    assert r["empty_car_init"] != r["init"]          # car.load = 0 really built another model
    assert r["load_after_reset"] == 1000.0
    assert r["init_after_error"] == r["init"]
    assert r["after_error"] == r["ref"] and r["after_terminate"] == r["ref"]
    assert [m for s, m in r["msgs_after_error"] if s >= 2] == []


def test_drive_errors_are_logged(fmus):
    r = job("drive_errors", fmus["drive"])
    bad = "\n".join(m for s, m in r["bad_param_msgs"] if s == 3)
    assert r["bad_param_init"] == 3 and "pretorque exceeds T_max" in bad and "Traceback" in bad   # fmi2Error
    assert r["ok"] == 0 and r["nan_step"] == 2 and r["recovered"] == 0
    assert "motor.speed = nan is not finite" in "\n".join(m for _, m in r["nan_msgs"])


def test_plant_accepts_any_communication_step(fmus):
    r = job("plant_step_sizes", fmus["plant"])
    assert r["status"] == [0] * 9 and r["fine_status"] == [0]
    assert r["errors_odd"] == [] and r["errors_fine"] == []
    check("end time, odd steps / 0.1 ms steps - 1 (sums of steps)", r["t_odd"] / r["t_fine"] - 1, 5e-13)
    # same held inputs, different partition of the time into steps: the same motion up to the
    # integration error of the internal generalized-alpha steps (<= 1 ms in both runs). Bounds relative
    # to the change since the start (position, velocity, motor angle, speed) and to the rope force
    # (traction sheave in / out)
    for i, name, tol in ((0, "car position", 3e-5), (1, "car velocity", 3e-5), (3, "motor angle", 2.5e-6),
                         (4, "motor speed", 2e-4)):
        a, b, a0 = r["odd"][i], r["fine"][i], r["start"][i]
        check(f"{name}: odd steps - 0.1 ms steps", a - b, tol * abs(b - a0) + 1e-9)
    for i, name, tol in ((5, "rope force in", 6e-6), (6, "rope force out", 5e-6)):
        a, b = r["odd"][i], r["fine"][i]
        check(f"traction sheave {name}: odd steps - 0.1 ms steps", a - b, tol * abs(b))
    assert r["odd"][0] > r["start"][0] + 0.01                     # the car moved up
