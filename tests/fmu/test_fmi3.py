"""FMI 3.0 co-simulation FMUs (`reeve-fmu build --fmi 3`): validation, the same variables as the FMI 2.0
FMUs plus arrays over them, the same results bit for bit (elevator and crane), state save/restore,
serialization and reset, early return at the brake release, bad calls of an FMI 3.0 host, the C host
through the FMI 3.0 API, clean exit.

The FMI 3.0 FMUs are built once per module with the CLI; the FMI 2.0 ones are the session's (`fmus`).
Every FMU-loading check runs in its own process (tests/support/fmi3_jobs.py via run_in_subprocess, the C
host, or scripts judged by their exit code).
"""
from __future__ import annotations

import re
import subprocess
import sys
import zipfile
from xml.etree import ElementTree as ET

import pytest

from reeve_fmu.fmu.native import loader_supported
from reeve_fmu.fmu.runner import run_in_subprocess
from tests.support import ROOT
from tests.support.fmu_host import chost

# the FMI 3.0 adapter is part of the native loader (SKIP_POLICY in tests/conftest.py allows this reason)
pytestmark = pytest.mark.skipif(not loader_supported(), reason="the native loader is built on Linux x86-64 only: elsewhere the FMI 3.0 build has no loader to wrap, so there is no FMI 3.0 FMU to test")

JOBS = str(ROOT / "tests" / "support" / "fmi3_jobs.py")
OK, DISCARD, ERROR = 0, 2, 3


@pytest.fixture(scope="module")
def fmus3(tmp_path_factory):
    dest = tmp_path_factory.mktemp("fmi3")
    p = subprocess.run([sys.executable, "-m", "reeve_fmu.cli", "build", "--fmi", "3", "--dest", str(dest)],
                       cwd=ROOT, capture_output=True, text=True, timeout=900)
    assert p.returncode == 0, p.stdout + p.stderr
    return {"plant": str(dest / "ReevingPlant.fmu"), "drive": str(dest / "ElectricDrive.fmu")}


@pytest.fixture(scope="module")
def crane_pairs(tmp_path_factory):
    """The crane scene's plant and drive FMUs, FMI 2.0 and 3.0, and the drive's start values."""
    import json

    out = {}
    for version in ("2", "3"):
        dest = tmp_path_factory.mktemp(f"crane{version}")
        p = subprocess.run([sys.executable, "-m", "reeve_fmu.cli", "build", "--fmi", version, "--scene",
                            str(ROOT / "scenes" / "slewing_crane.toml"), "--dest", str(dest)],
                           cwd=ROOT, capture_output=True, text=True, timeout=900)
        assert p.returncode == 0, p.stdout + p.stderr
        out[version] = {"plant": str(dest / "CranePlant.fmu"), "drive": str(dest / "CraneDrive.fmu"),
                        "drive_values": json.loads((dest / "CranePlant.drive.json").read_text())["drive"]}
    return out


def _md(fmu):
    with zipfile.ZipFile(fmu) as zf:
        return ET.fromstring(zf.read("modelDescription.xml")), zf.namelist()


def _variables2(root):
    out = {}
    for sv in root.find("ModelVariables"):
        t = sv[0]
        out[sv.get("name")] = {**sv.attrib, **t.attrib, "type": t.tag}
    return out


def _variables3(root):
    return {v.get("name"): {**v.attrib, "type": v.tag} for v in root.find("ModelVariables")}


# ------------------------------------------------------------------------------------------------
# build and modelDescription
# ------------------------------------------------------------------------------------------------
def test_fmi3_fmus_validate_and_declare_the_fmi2_variables(fmus, fmus3):
    """fmpy validate finds no problems; every FMI 2.0 variable is there with the same attributes, its value
    reference + 1 (0 is `time`, as in the FMI 3.0 Reference FMUs); outputs, their dependencies and the
    initial unknowns correspond; the binaries are the loader's, under x86_64-linux."""
    kinds = {"Real": "Float64", "Integer": "Int32", "Boolean": "Boolean", "String": "String"}
    for key in ("plant", "drive"):
        p = subprocess.run([sys.executable, "-m", "fmpy", "validate", fmus3[key]], capture_output=True, text=True,
                           timeout=600)
        assert p.returncode == 0 and "No problems found" in p.stdout, p.stdout + p.stderr
        r2, _ = _md(fmus[key])
        r3, names = _md(fmus3[key])
        assert r3.get("fmiVersion") == "3.0" and re.fullmatch(r"\{[0-9a-f-]{36}\}", r3.get("instantiationToken"))
        model = r3.find("CoSimulation").get("modelIdentifier")
        assert sorted(n for n in names if n.startswith("binaries/")) == sorted(
            f"binaries/x86_64-linux/{model}{s}.so" for s in ("", "_pythonfmu", "_pyexit"))
        cs = r3.find("CoSimulation").attrib
        assert cs["canGetAndSetFMUState"] == cs["canSerializeFMUState"] == "true"
        assert cs["hasEventMode"] == "true" and cs["providesIntermediateUpdate"] == "false"
        assert cs["mightReturnEarlyFromDoStep"] == "true"
        v2, v3 = _variables2(r2), _variables3(r3)
        arrays = {n: v3.pop(n) for n in [n for n in v3 if n not in v2 and n != "time"]}
        _check_arrays(arrays, v2, zipfile.ZipFile(fmus3[key]).read("resources/reeve_fmi3_arrays.txt").decode(), key)
        assert v3.pop("time") == {"name": "time", "valueReference": "0", "causality": "independent",
                                  "variability": "continuous", "description": "Simulation time", "unit": "s",
                                  "type": "Float64"}
        assert set(v3) == set(v2), key
        index_to_vr = {i: int(d["valueReference"]) + 1 for i, d in enumerate(v2.values(), start=1)}
        for name, a in v2.items():
            b = v3[name]
            assert b["type"] == kinds[a["type"]] and int(b["valueReference"]) == int(a["valueReference"]) + 1
            for attr in ("causality", "variability", "initial", "unit", "displayUnit", "declaredType", "start",
                         "min", "max", "description"):
                assert a.get(attr) == b.get(attr), (key, name, attr)
            if "derivative" in a:
                assert int(b["derivative"]) == index_to_vr[int(a["derivative"])], name
        outs2 = [(index_to_vr[int(u.get("index"))],
                  sorted(index_to_vr[int(i)] for i in u.get("dependencies", "").split()))
                 for u in r2.find("ModelStructure/Outputs")]
        outs3 = [(int(u.get("valueReference")), sorted(int(i) for i in u.get("dependencies", "").split()))
                 for u in r3.find("ModelStructure").iter("Output")
                 if int(u.get("valueReference")) not in {int(a["valueReference"]) for a in arrays.values()}]
        assert outs3 == outs2 and outs3
        output_arrays = [int(a["valueReference"]) for a in arrays.values() if a["causality"] == "output"]
        assert [int(u.get("valueReference")) for u in r3.find("ModelStructure").iter("InitialUnknown")] == \
            [index_to_vr[int(u.get("index"))] for u in r2.find("ModelStructure/InitialUnknowns")] + output_arrays


#: the FMI 3.0 arrays over the scalars: name -> element names
ARRAYS = {"plant": {f"sheaves.{q}": [f"{s}.{q}" for s in ("car_sheave", "traction", "cw_sheave")]
                    for q in ("angle", "speed", "tension_in", "tension_out")},
          "drive": {"landings": [f"landing[{k}]" for k in range(1, 9)],
                    "pretorques": [f"pretorque[{k}]" for k in range(1, 9)],
                    "trip.targets": [f"trip.target[{k}]" for k in range(1, 17)]}}


def _check_arrays(arrays, v2, table, key):
    """Each array has the size, type, causality, unit of its scalars and their start values; the
    adapter's table maps it onto the scalars' FMI 2.0 value references."""
    assert set(arrays) == set(ARRAYS[key]), key
    rows = {int(line.split()[0]): [int(x) for x in line.split()[1:]] for line in table.splitlines()}
    for name, a in arrays.items():
        elems = [v2[e] for e in ARRAYS[key][name]]
        kind = {"Real": "Float64", "Integer": "Int32"}[elems[0]["type"]]
        assert a["type"] == kind and a["causality"] == elems[0]["causality"], name
        assert a.get("unit") == elems[0].get("unit") and a.get("declaredType") == elems[0].get("declaredType")
        if "start" in elems[0]:
            assert a["start"].split() == [e["start"] for e in elems], name
        assert rows[int(a["valueReference"])] == [len(elems)] + [int(e["valueReference"]) for e in elems], name


# ------------------------------------------------------------------------------------------------
# results and state
# ------------------------------------------------------------------------------------------------
def test_fmi3_trip_equals_the_fmi2_trip_bit_for_bit(fmus, fmus3):
    """fmpy's FMI 3.0 co-simulation (FMU3Slave) and its FMI 2.0 one (FMU2Slave), the same Gauss-Seidel
    loop at 1 ms over the first 4 s of the R1 trip (pre-torque, brake lift, acceleration to 1.6 m/s):
    the recorded plant outputs are equal as floats. No event falls inside a step here; the adapter adds
    nothing but the interface."""
    n = 4000
    a = run_in_subprocess(f"{JOBS}:trip", fmus["plant"], fmus["drive"], n, timeout=900)
    b = run_in_subprocess(f"{JOBS}:trip", fmus3["plant"], fmus3["drive"], n, timeout=900)
    assert (a["fmi3"], b["fmi3"]) == (False, True)
    assert len(b["rows"]) == n and b["rows"] == a["rows"]
    assert b["rows"][-1][1] > 1.5          # the car runs at rated speed: the window covers the start


def test_fmi3_crane_equals_the_fmi2_crane_bit_for_bit(crane_pairs):
    """The crane scene's FMUs built with --fmi 3 validate, and their co-simulation (slew by speed,
    hoist, 5 ms, 3 s) equals the FMI 2.0 pair's bit for bit; the payload's position, rotation and
    rotation rate read as FMI 3.0 arrays are their x, y, z scalars."""
    rows = {}
    for version, f in crane_pairs.items():
        for key in ("plant", "drive"):
            p = subprocess.run([sys.executable, "-m", "fmpy", "validate", f[key]], capture_output=True, text=True,
                               timeout=600)
            assert p.returncode == 0, p.stdout + p.stderr
        r = run_in_subprocess(f"{JOBS}:crane", f["plant"], f["drive"], f["drive_values"], 600, timeout=900)
        assert r["fmi3"] == (version == "3")
        rows[version] = r["rows"]
        for name, (array, scalars) in r["vectors"].items():      # FMI 3.0: the vectors are their scalars
            assert array == scalars, name
        assert len(r["vectors"]) == (3 if version == "3" else 0)
    assert len(rows["3"]) == 600 and rows["3"] == rows["2"]
    assert rows["3"][-1][2] != rows["3"][0][2]      # the jib turned


def test_fmi3_arrays_are_the_scalars(fmus, fmus3):
    """The trip with the drive's pre-torques set through the array `pretorques` and the plant's sheave
    forces read through `sheaves.tension_in` every step: the array equals its three scalars at every
    step, a read of an array and a scalar together returns both, and the trip equals the FMI 2.0 trip
    (pre-torques set as scalars) bit for bit."""
    n = 2000
    a = run_in_subprocess(f"{JOBS}:trip", fmus["plant"], fmus["drive"], n, timeout=900)
    r = run_in_subprocess(f"{JOBS}:arrays", fmus3["plant"], fmus3["drive"], n, timeout=900)
    assert r["same"] and r["rows"] == a["rows"]
    assert r["scalars"] == ["car_sheave.tension_in", "traction.tension_in", "cw_sheave.tension_in"]
    assert r["both"] == r["tension"] + [r["car"]]
    assert r["pretorques"][:2] == [522.2, 331.3]
    assert r["mismatch"] == [ERROR, ["plant: fmi3GetFloat64: nValues = 1, but the 1 value reference(s) hold "
                                     "3 value(s)"]]


def test_fmi3_early_return_at_the_brake_release(fmus, fmus3):
    """At 10 ms communication steps with earlyReturnAllowed, the plant's step from 0.71 s, in which the
    brake releases (brake.engaged, a 20 ms lag after the command, crosses 1/2), ends early with the
    reason logged, at the end of the solver step (1 ms) in which it crossed: the same step redone from
    the saved state in 1 ms doSteps crosses in the solver step ending at that time, with the same
    engagement. The steps before it equal the FMI 2.0 run at 10 ms bit for bit (a step without an event
    is the normal step), and without earlyReturnAllowed the same steps never return early (trip job)."""
    h = 0.01
    r = run_in_subprocess(f"{JOBS}:early_return", fmus3["plant"], fmus3["drive"], h, 300, timeout=900)
    hit = r["hit"]
    assert hit is not None and hit["t"] == 0.71 and hit["last"] == hit["time"]
    assert hit["log"] == [f"early return at t = {hit['last']!r} s (step 0.71 + 0.01 s): the brake releases"]
    crossed = [row for row in r["fine"] if row[1] < 0.5]
    assert [row[0] for row in r["fine"] if row[1] >= 0.5][-1] < crossed[0][0]      # one crossing
    assert abs(crossed[0][0] - hit["last"]) < 1e-12 and crossed[0][1] == hit["engaged"] < 0.5 <= hit["engaged0"]
    assert not any(row[2] for row in r["fine"])     # one solver step per doStep: never early
    a = run_in_subprocess(f"{JOBS}:trip", fmus["plant"], fmus["drive"], len(r["rows"]) + 1, h, timeout=900)
    b = run_in_subprocess(f"{JOBS}:trip", fmus3["plant"], fmus3["drive"], len(r["rows"]) + 1, h, timeout=900)
    assert r["rows"] == a["rows"][:len(r["rows"])] and b["rows"] == a["rows"] and len(r["rows"]) == 71


def test_slip_onset_ends_a_step_at_the_solver_step_where_the_rope_starts_to_slip():
    """Plant.step_to_event (what the FMI 3.0 plant runs with early return) on the slipping traction sheave
    of scenes/hard/traction_en81.toml, the motor torque raised by 100 N.m every 10 ms step from the
    holding torque: the step from 0.10 s ends at 0.108 s, "traction starts to slip", the groove-friction
    deflection past the sticking band 0.9 creep; the same step redone from its start in 1 ms doSteps
    (step(), no event search) leaves the band first at that solver step, inside it one step before."""
    from reeve_fmu.components.plant import Plant
    from reeve_fmu.core.kernel import IN_TRAC_Z

    p = Plant(ROOT / "scenes" / "hard" / "traction_en81.toml")
    band = 0.9 * p.model.K.trac_zmax
    h0 = p.holding_torque()
    p.start_with_torque(h0)
    hit = None
    for k in range(15):
        t0, saved, y0 = p.state.t, p.state.copy(), p._y
        _, te, event = p.step_to_event(0.01, h0 + 100.0 * k, 1.0)
        if event is not None:
            hit = (k, t0, te, event, abs(p.state.info[IN_TRAC_Z]))
            break
        assert abs(p.state.info[IN_TRAC_Z]) <= band
    assert hit is not None and hit[3] == "traction starts to slip" and hit[4] > band
    k, t0, te, _, _ = hit
    assert abs(t0 - 0.1) < 1e-12 and abs(te - 0.108) < 1e-12
    p.state, p._y = saved, y0
    fine = []
    for j in range(1, 11):
        p.step(t0 + j * 1e-3 - p.state.t, h0 + 100.0 * k, 1.0)
        fine.append((p.state.t, abs(p.state.info[IN_TRAC_Z]) > band))
    first = next(t for t, out in fine if out)
    assert abs(first - te) < 1e-12 and not any(out for t, out in fine if t < te - 1e-12)


def test_an_empty_drum_ends_a_step_at_the_last_solver_step_before_it():
    """scenes/crane_two_fall_hoist.toml with 0.5 m of rope on the drum (the rope 99.5 m shorter), solver
    step 1 ms, the winch released with the motor torque 0: the light drum spins up, its rope goes slack
    (tension-only) and it pays out the 0.5 m; in 1 ms steps (step()) the solver stops after 52-53 ms
    (measured), the drum empty; in 10 ms steps (step_to_event) the step that crosses that instant ends
    early at that last good solver step with the reason, and the next step raises the solver's error."""
    from dataclasses import replace

    from reeve_fmu.components.plant import Plant
    from reeve_fmu.core.scene import load_scene
    from reeve_fmu.core.solver import SolverError

    sc = load_scene(ROOT / "scenes" / "crane_two_fall_hoist.toml")
    sc = replace(sc, sheaves=tuple(replace(s, stored=0.5) if s.kind == "drum" else s for s in sc.sheaves),
                 ropes=tuple(replace(r, length=r.length - 99.5) for r in sc.ropes),
                 solver=replace(sc.solver, step=1e-3))
    fine = Plant(sc)
    with pytest.raises(SolverError, match="its stored length reached 0 m"):
        for _ in range(1000):
            fine.step(1e-3, 0.0, 1.0)
    t_empty = fine.state.t
    assert 0.04 < t_empty < 0.07 and abs(t_empty * 1e3 - round(t_empty * 1e3)) < 1e-9   # on the 1 ms grid
    p = Plant(sc)
    events = []
    with pytest.raises(SolverError, match="drum 'drum' \\(its stored length reached 0 m\\)"):
        for _ in range(100):
            t0 = p.state.t
            _, te, event = p.step_to_event(0.01, 0.0, 1.0)
            events.append((t0, te, event))
    t0, te, event = events[-1]
    assert abs(te - fine.state.t) < 1e-9 and t0 < te < t0 + 0.01
    assert event.startswith(f"the solver stops: t = {t_empty:.6f} s: a drum has no stored rope left")
    assert p.state.t == te


def test_master_runs_fmi3_fmus_with_early_return_as_the_fmi2_fmus_when_no_event_falls_inside_a_step(fmus, fmus3):
    """cosimulate at 1 ms over the first 2 s of the R1 trip (pre-torque, brake release, start): the FMI
    3.0 pair with early return (the default) records what the FMI 2.0 pair records, bit for bit, with no
    early return (the plant's solver step is the communication step; the drive's commands fall on the
    grid); at 10 ms the FMI 3.0 pair's plant returns early at the brake release (0.714 s)."""
    a = run_in_subprocess(f"{JOBS}:master", fmus["plant"], fmus["drive"], 2.0, 1e-3, timeout=900)
    b = run_in_subprocess(f"{JOBS}:master", fmus3["plant"], fmus3["drive"], 2.0, 1e-3, timeout=900)
    assert a["events"] is None and b["events"] == []
    assert b["rows"] == a["rows"] and len(a["rows"][0]) == 2001 and a["rows"][1][-1] > 0.1
    c = run_in_subprocess(f"{JOBS}:master", fmus3["plant"], fmus3["drive"], 2.0, 1e-2, timeout=900)
    assert len(c["events"]) == 1 and abs(c["events"][0] - 0.714) < 1e-12


def test_master_early_return_makes_the_brake_stop_coupling_error_smaller(fmus, fmus3):
    """benchmarks/brake_stop_coupling.py with the drive tuned for 10 ms coupling: the brake stop after a
    3 m move, Gauss-Seidel at 10 ms, against the monolithic 0.1 ms reference. The FMI 2.0 pair gets the
    brake apply command at the communication point before the drive's tick (the drive steps over it):
    the brake reaches half engagement 4.7 ms early (measured). The FMI 3.0 pair with early return (the
    drive's step ends at its command switch, the plant's at brake engagement; the master steps the
    other FMU to that time): 0.05 ms, the reference's own resolution (its 0.1 ms step); ratio 94
    measured. The stop's travel error falls too: 0.060 -> 0.049 mm measured (ratio 0.82; the rest is the
    coupled speed loop's torque held at the apply command, 506.7 N.m against the reference's 508.9)."""
    r = run_in_subprocess(f"{ROOT / 'benchmarks' / 'brake_stop_coupling.py'}:measure",
                          (fmus["plant"], fmus["drive"]), (fmus3["plant"], fmus3["drive"]), 0.01, ["10 ms"],
                          timeout=1800)["10 ms"]
    a, b = r["FMI 2.0"], r["FMI 3.0 early return"]
    assert a["events"] == [] and len(b["events"]) == 2 and abs(b["events"][0] - r["t_apply"]) < 1.25e-4
    assert 4e-3 < a["engage_instant_error_s"] < 5e-3
    assert b["engage_instant_error_s"] < 0.2e-3 and b["engage_instant_error_s"] < a["engage_instant_error_s"] / 20
    assert b["stop_travel_error_m"] < a["stop_travel_error_m"]


def test_fmi3_state_rewind_serialization_and_reset_are_exact(fmus3):
    """fmi3GetFMUState / SetFMUState / Serialize / Deserialize on both FMUs after 1.5 s: re-running the
    next 0.5 s from the saved and from the deserialized state repeats the first run bit for bit, and
    `time` follows the restored state; after fmi3Reset both FMUs run the 2 s again bit for bit."""
    r = run_in_subprocess(f"{JOBS}:state", fmus3["plant"], fmus3["drive"], 1500, 500, timeout=900)
    assert r["rewound"] == r["first"] and r["restored"] == r["first"] and r["after_reset"] == r["first"]
    assert r["first"][0] != r["first"][-1] and all(b > 0 for b in r["bytes"])
    assert r["time_after"] == 2.0


# ------------------------------------------------------------------------------------------------
# bad calls: fmi3Error with the reason logged, never a crash
# ------------------------------------------------------------------------------------------------
EXPECTED = {  # call: (status, words of the logged reason)
    "doStep_before_init": (ERROR, "fmi3DoStep called in state Instantiated"),
    "exit_before_enter": (ERROR, "fmi3ExitInitializationMode called in state Instantiated"),
    "event_mode": (ERROR, "fmi3EnterEventMode called in state Instantiated"),
    "enter_twice": (ERROR, "fmi3EnterInitializationMode called in state Step Mode"),
    "nvalues_mismatch": (ERROR, "nValues = 3, but the 2 value reference(s) hold 2 value(s)"),
    "array_nvalues": (ERROR, "nValues = 1, but the 1 value reference(s) hold 8 value(s)"),
    "set_time": (ERROR, "value reference 0 is the independent variable time"),
    "set_output": (ERROR, "motor.torque is not a settable Real variable"),
    "unknown_vr": (ERROR, "is not a Real variable"),
    "set_nan": (ERROR, "motor.speed = nan is not finite"),
    "step_after_nan": (ERROR, "invalid inputs were rejected"),
    "int8": (ERROR, "fmi3GetInt8: value reference"),
    "directional_derivative": (ERROR, "fmi3GetDirectionalDerivative is not supported"),
    "refused_after_errors": (ERROR, "refused because of earlier call errors"),
    "time_jump": (ERROR, "currentCommunicationPoint=0.5 but the FMU is at t=0.001"),
    "negative_step": (ERROR, "communicationStepSize=-0.001"),
    "terminate_twice": (ERROR, "fmi3Terminate called in state Terminated"),
}


def test_fmi3_bad_calls_return_error_with_the_reason_and_the_instance_goes_on(fmus3):
    r = run_in_subprocess(f"{JOBS}:bad_calls", fmus3["drive"], timeout=600)
    for call, (status, words) in EXPECTED.items():
        got, log = r[call]
        assert got == status, (call, got, log)
        assert any(words in m for m in log), (call, log)
    for call in ("empty_int8", "ok_step", "ok_step_after"):
        assert r[call] == [OK, []], (call, r[call])
    assert r["time"] == 2e-3


def test_fmi3_intermediate_variables_request_is_refused_with_the_reason(fmus3):
    r = run_in_subprocess(f"{JOBS}:instantiate_refused", fmus3["drive"], timeout=600)
    assert r["instantiated"] is False
    assert any("intermediate variables were requested, but this FMU has no Intermediate Update Mode" in m
               for m in r["log"]), r


def test_fmi3_event_mode_state_machine(fmus3):
    """eventModeUsed: fmi3ExitInitializationMode enters Event Mode (fmi3DoStep there is refused),
    fmi3UpdateDiscreteStates reports nothing to update and no time event, fmi3EnterStepMode leaves it.
    At 10 ms the plant's step over the brake release returns early with eventHandlingNeeded; in Event
    Mode the host sets inputs and reads outputs at the event time, then the rest of the step ends on the
    grid. Calls out of order (Event Mode before initialization, Step Mode twice, fmi3UpdateDiscreteStates
    in Step Mode, fmi3DoStep in Event Mode, Event Mode on an instance without eventModeUsed) are
    fmi3Error with the reason, and the instance goes on."""
    r = run_in_subprocess(f"{JOBS}:event_mode", fmus3["plant"], fmus3["drive"], 0.01, 300, timeout=900)
    refused = {"enter_event_before_init": "fmi3EnterEventMode called in state Instantiated",
               "step_in_event_mode": "fmi3DoStep called in state Event Mode",
               "enter_step_twice": "fmi3EnterStepMode called in state Step Mode",
               "update_in_step_mode": "fmi3UpdateDiscreteStates called in state Step Mode",
               "step_before_step_mode": "fmi3DoStep called in state Event Mode",
               "drive_event_mode": "fmi3EnterEventMode: the instance was created with eventModeUsed = false"}
    for call, words in refused.items():
        status, log = r[call]
        assert status == ERROR and any(words in m for m in log), (call, r[call])
    no_update = [False, False, False, False, False, 0.0]
    assert r["update_after_init"] == r["update"] == no_update
    for call in ("enter_step", "enter_event", "set_in_event_mode", "enter_step_after_event", "rest",
                 "terminate_in_event_mode"):
        assert r[call] == [OK, []], (call, r[call])
    hit = r["hit"]      # the brake release of test_fmi3_early_return_at_the_brake_release, now an event
    assert hit["t"] == 0.71 and hit["event"] and hit["early"] and hit["t"] < hit["last"] == hit["time"] < 0.72
    assert r["get_in_event_mode"][0] == hit["last"] and r["get_in_event_mode"][1] < 0.5
    assert r["time_after"] == 0.72


# ------------------------------------------------------------------------------------------------
# hosts
# ------------------------------------------------------------------------------------------------
def test_c_host_through_the_fmi3_api_equals_its_fmi2_run(fmus, fmus3, host, tmp_path):
    """The C host (no LD_PRELOAD, no PYTHONPATH, logging off) runs both FMI 3.0 FMUs through
    fmi3InstantiateCoSimulation ... fmi3DoStep ... fmi3FreeInstance for 2 s of the trip, exits 0, and
    records what the same host records through the FMI 2.0 API with the FMI 2.0 FMUs, bit for bit."""
    steps, h = 2000, 1e-3
    record = ["car.position", "car.velocity", "motor.speed", "traction.tension_in"]
    rows = {}
    for version, f in (("2", fmus), ("3", fmus3)):
        dirs = {k: str(chost.extract(f[k], tmp_path / version / k)) for k in ("plant", "drive")}
        plan = chost.cosim_plan(f["plant"], f["drive"], dirs["plant"], dirs["drive"], step=h, steps=steps,
                                drive_values={"pretorque[1]": 522.5, "pretorque[2]": 331.5}, record=record,
                                drive_record=["motor.torque"], stop_time=steps * h)
        assert ("fmi 3" in plan) == (version == "3")
        r = chost.run_host(host, plan, tmp_path / version)
        assert r["returncode"] == 0, r["stdout"] + r["stderr"]
        assert "[ERROR]" not in r["stderr"] and "[FATAL]" not in r["stderr"], r["stderr"]
        rows[version] = r["rows"]
    assert len(rows["3"]) == steps + 1 and rows["3"] == rows["2"]
    assert rows["3"][-1][1] > 0.1          # the car moved


SCRIPT = """
from fmpy import simulate_fmu
for fmu in ({drive!r}, {plant!r}):
    r = simulate_fmu(fmu, stop_time=0.01, output_interval=1e-3)
    assert len(r) == 11, len(r)
"""


def test_fmi3_fmpy_scripts_exit_cleanly(fmus3, tmp_path):
    """A plain fmpy script running simulate_fmu (FMI 3.0 co-simulation) of both FMUs, 10 runs: every run
    exits 0."""
    code = SCRIPT.format(plant=fmus3["plant"], drive=fmus3["drive"])
    assert chost.failed_runs({"fmi3_pair": code}, tmp_path, chost.clean_env()) == []
