"""Jobs for tests/fmu/test_plant_fmu.py and tests/fmu/test_cosim.py, each run in a fresh interpreter by
reeve_fmu.fmu.runner.run_in_subprocess (one process per FMU-loading job, docs/cosim.md, 'pythonfmu and fmpy' item 4).

FMU jobs load the runner *by file path* and do not import reeve_fmu from the checkout: the FMUs then
run the package they carry (bootstrapped into ~/.cache/reeve_fmu/<source hash>/, where numba's cache
persists across runs), exactly as under any third-party fmpy host. Jobs that also need the Python
side of reeve_fmu (the fmpy master, the monolithic reference) import it *through the FMU's shim*
(`_fmu_package`), so master, FMUs and reference all run the same package copy. Results travel as
JSON (floats exactly).
"""
import importlib.util
import math
import os
import shutil
import sys
import tempfile
import zipfile

try:
    import fcntl   # the build lock of ensure_test_fmus (POSIX)
except ImportError:  # pragma: no cover - Windows
    fcntl = None

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
DT = 1e-3


def _runner():
    name = "_reeve_runner_standalone"
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(
        name, os.path.join(REPO, "reeve_fmu", "fmu", "runner.py"))
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod
    spec.loader.exec_module(mod)
    return mod


def _fmu_package(fmu):
    """Import reeve_fmu the way the FMU does (its resources' bootstrap shim -> stable cache copy)."""
    assert "reeve_fmu" not in sys.modules, "reeve_fmu was imported before the FMU package"
    tmp = tempfile.mkdtemp(prefix="reeve_job_pkg_")
    with zipfile.ZipFile(fmu) as zf:
        for item in zf.namelist():
            if item.startswith("resources/reeve_fmu"):
                zf.extract(item, tmp)
    # executed as the module `reeve_fmu`, the shim puts the package it bootstraps in its place
    spec = importlib.util.spec_from_file_location("reeve_fmu", os.path.join(tmp, "resources", "reeve_fmu.py"))
    shim = importlib.util.module_from_spec(spec)
    sys.modules["reeve_fmu"] = shim
    spec.loader.exec_module(shim)
    reeve_fmu = sys.modules["reeve_fmu"]
    shutil.rmtree(tmp, ignore_errors=True)
    assert "reeve_fmu_vendor" not in reeve_fmu.__file__, reeve_fmu.__file__
    return reeve_fmu


def _host_package():
    """Import reeve_fmu from this checkout before any FMU loads: the FMUs then run the host's package
    (same sources as the FMUs' vendored copy unless the tree changed since the build; the FMU logs a
    warning then) and share its numba cache with the rest of the test suite. The checkout is on the
    path: run_in_subprocess puts it on the job's PYTHONPATH."""
    import reeve_fmu

    return reeve_fmu


def _msgs(h):
    return [(m.status, m.message) for m in h.messages]


# ---------------------------------------------------------------------------------------------- plant
PLANT_OUTS = ["car.position", "car.velocity", "car.acceleration", "motor.angle", "motor.speed",
              "traction.tension_in", "traction.tension_out", "traction.traction_ratio", "brake.torque",
              "brake.engaged", "hoist.tension_start"]


def _tau(i):
    """Torque schedule around the R1 holding torque; the brake opens at step 30."""
    return 522.5 + (120.0 if (i // 40) % 2 == 0 else -90.0) + 0.3 * i


def _brake(i):
    return 1.0 if i >= 30 else 0.0


def _run_plant(h, i0, n, dt=DT):
    out = []
    for i in range(i0, i0 + n):
        h.set("motor.torque", _tau(i))
        h.set("brake.command", _brake(i))
        st = h.step(dt)
        if st != 0:
            raise RuntimeError(f"step {i} returned status {st}:\n{h.log_text()}")
        out.append(h.get_many(PLANT_OUTS))
    return out


def plant_rewind(fmu):
    """get/set FMU state: rewind and re-step bit-identically; also restore twice."""
    r = _runner()
    with r.SlaveHandle.open(fmu, "plant") as h:
        h.setup(0.0)
        first = h.get_many(PLANT_OUTS)
        _run_plant(h, 0, 60)
        t_snap = h.time
        snap_out = h.get_many(PLANT_OUTS)
        s = h.get_state()
        a = _run_plant(h, 60, 120)
        h.set_state(s, time=t_snap)
        restored = h.get_many(PLANT_OUTS)
        b = _run_plant(h, 60, 120)
        h.set_state(s, time=t_snap)
        c = _run_plant(h, 60, 120)
        h.free_state(s)
        import reeve_fmu

        return {"first": first, "a": a, "b": b, "c": c, "snap_out": snap_out, "restored": restored,
                "errors": [str(m) for m in h.errors(1)], "pkg_file": reeve_fmu.__file__}


def plant_serialize_source(fmu):
    """Run 60 steps, serialize, continue 120 (reference); a second instance in this process (with
    other parameters) restores the blob and must continue identically."""
    _host_package()
    r = _runner()
    with r.SlaveHandle.open(fmu, "src") as h:
        h.setup(0.0)
        _run_plant(h, 0, 60)
        t = h.time
        s = h.get_state()
        blob = h.serialize_state(s)
        h.free_state(s)
        ref = _run_plant(h, 60, 120)
        with r.SlaveHandle.open(fmu, "dst", unzip_dir=h.unzip_dir) as g:
            g.setup(0.0, start_values={"car.load": 0.0})      # other model; the state brings its own
            st = g.deserialize_state(blob)
            g.set_state(st, time=t)
            g.free_state(st)
            same = {"cont": _run_plant(g, 60, 120), "load": g.get("car.load"),
                    "errors": [str(m) for m in g.errors()]}
        return {"blob": blob.decode("latin-1"), "t": t, "ref": ref, "same_proc": same, "size": len(blob),
                "errors": [str(m) for m in h.errors()]}


def _continue_serialized(fmu, blob, t, run):
    """A new instance in this (new) process restores a serialized FMU state at t and continues with
    run(handle); returns (run's result, logged errors)."""
    _host_package()
    r = _runner()
    with r.SlaveHandle.open(fmu, "dst") as h:
        h.setup(0.0)
        st = h.deserialize_state(blob.encode("latin-1"))
        h.set_state(st, time=t)
        h.free_state(st)
        return run(h), [str(m) for m in h.errors()]


def plant_serialize_target(fmu, blob, t):
    cont, errors = _continue_serialized(fmu, blob, t, lambda h: _run_plant(h, 60, 120))
    return {"cont": cont, "errors": errors}


def plant_errors(fmu):
    """NaN torque and a solver failure reach the master as logged errors + discard."""
    _host_package()
    r = _runner()
    res = {}
    with r.SlaveHandle.open(fmu, "plant") as h:
        h.setup(0.0)
        _run_plant(h, 0, 40)
        t0 = h.time
        s = h.get_state()
        mark = len(h.messages)
        h.set("motor.torque", float("nan"))
        res["nan_step"] = h.step(DT)
        res["nan_msgs"] = _msgs(h)[mark:]
        h.set("motor.torque", 500.0)
        res["after_nan"] = h.step(DT)
        t1 = h.time
        # drive the car into the machine: 1 MN m for 0.3 s in ONE communication step
        mark = len(h.messages)
        res["before_crash"] = h.get_many(PLANT_OUTS)
        h.set("motor.torque", 1.0e6)
        res["crash_step"] = h.do_step(t1, 0.3)
        res["crash_msgs"] = _msgs(h)[mark:]
        res["after_crash"] = h.get_many(PLANT_OUTS)     # the last good outputs stay readable
        mark = len(h.messages)
        h.set("motor.torque", 500.0)
        res["dirty_step"] = h.do_step(t1, DT)
        res["dirty_msgs"] = _msgs(h)[mark:]
        h.set_state(s, time=t0)
        h.set("motor.torque", 500.0)
        res["after_restore"] = h.step(DT)
        res["bad_dt"] = h.do_step(h.time, -1.0)
        mark = len(h.messages)
        h.set("brake.command", 2.0)
        res["brake_out_of_range_step"] = h.step(DT)
        res["brake_msgs"] = _msgs(h)[mark:]
        h.set("brake.command", 1.0)
        res["final"] = h.step(DT)
        h.free_state(s)
    return res


def plant_reset(fmu):
    """fmi2Reset on the plant FMU: a clean 80-step run of a fresh instance (reference); reset after a
    normal run, a run with car.load = 0 driven into errors (NaN torque, then a solver failure that
    leaves the instance faulty); reset from that error state; then the same 80 steps again; and once
    more after terminate + reset. The runs after each reset must equal the reference bit for bit."""
    _host_package()
    r = _runner()
    res = {}
    with r.SlaveHandle.open(fmu, "plant") as h:
        h.setup(0.0)
        res["init"] = h.get_many(PLANT_OUTS)
        res["ref"] = _run_plant(h, 0, 80)
        h.reset()                                      # from stepComplete, without terminate
        h.setup(0.0, start_values={"car.load": 0.0})   # another model: empty car
        res["empty_car_init"] = h.get_many(PLANT_OUTS)
        _run_plant(h, 0, 40)
        mark = len(h.messages)
        h.set("motor.torque", float("nan"))
        res["nan_step"] = h.step(DT)
        h.set("motor.torque", 1.0e6)                   # 1 MN m for 0.3 s: the car hits the machine
        res["crash_step"] = h.do_step(h.time, 0.3)
        h.set("motor.torque", 500.0)
        res["refused_step"] = h.step(DT)
        res["error_msgs"] = _msgs(h)[mark:]
        h.reset()                                      # from the error state
        mark = len(h.messages)
        h.setup(0.0)
        res["load_after_reset"] = h.get("car.load")
        res["init_after_error"] = h.get_many(PLANT_OUTS)
        res["after_error"] = _run_plant(h, 0, 80)
        res["msgs_after_error"] = _msgs(h)[mark:]
        h.terminate()
        h.reset()                                      # from terminated
        h.setup(0.0)
        res["after_terminate"] = _run_plant(h, 0, 80)
    return res


def plant_step_sizes(fmu):
    """Any communication step: after the brake has opened (100 x 1 ms), a sequence of odd steps covers
    the same time as 0.1 ms steps; the motion must agree up to the integration error."""
    _host_package()
    r = _runner()
    steps = [1e-4, 3.7e-4, 1e-3, 2.5e-3, 1.3e-3, 1e-2, 4.3e-4, 0.0317, 0.2]
    total = sum(steps)
    out = {}
    for label in ("odd", "fine"):
        with r.SlaveHandle.open(fmu, label) as h:
            h.setup(0.0)
            h.set("brake.command", 1.0)
            h.set("motor.torque", 700.0)
            for _ in range(100):
                h.step(DT)
            out["start"] = h.get_many(PLANT_OUTS)
            if label == "odd":
                out["status"] = [h.step(dt) for dt in steps]
            else:
                n = int(round(total / 1e-4))
                out["fine_status"] = sorted(set(h.step(total / n) for _ in range(n)))
            out["t_" + label] = h.time
            out[label] = h.get_many(PLANT_OUTS)
            out["errors_" + label] = [str(m) for m in h.errors()]
    out["total"] = total
    return out


# ---------------------------------------------------------------------------------------------- drive
DRIVE_OUTS = ["motor.torque", "brake.command", "car.position_ref", "car.velocity_ref", "drive.torque_ref",
              "motor.current_q", "drive.phase"]


def _run_drive(h, i0, n):
    """Feed the drive a plausible measurement: a rigid car following 95 % of its speed reference."""
    out = []
    for i in range(i0, i0 + n):
        w = 0.95 * h.get("motor.speed_ref")
        h.set("motor.speed", w)
        h.set("motor.angle", h.get("motor.angle") + w * DT)
        st = h.step(DT)
        if st != 0:
            raise RuntimeError(f"step {i} returned status {st}:\n{h.log_text()}")
        out.append(h.get_many(DRIVE_OUTS))
    return out


def drive_state(fmu, level):
    _host_package()
    r = _runner()
    with r.SlaveHandle.open(fmu, "drive") as h:
        h.setup(0.0, start_values={"drive.level": level, "trip.start_delay": 0.1})
        _run_drive(h, 0, 700)                      # into the run phase
        t = h.time
        s = h.get_state()
        blob = h.serialize_state(s)
        a = _run_drive(h, 700, 300)
        h.set_state(s, time=t)
        b = _run_drive(h, 700, 300)
        h.free_state(s)
        with r.SlaveHandle.open(fmu, "dst", unzip_dir=h.unzip_dir) as g:
            g.setup(0.0)                          # Level 1 default: the state brings level & params
            st = g.deserialize_state(blob)
            g.set_state(st, time=t)
            g.free_state(st)
            c = _run_drive(g, 700, 300)
            lvl = g.get("drive.level")
            errs_g = [str(m) for m in g.errors()]
        return {"a": a, "b": b, "c": c, "level_restored": lvl, "blob": blob.decode("latin-1"), "t": t,
                "errors": [str(m) for m in h.errors()] + errs_g}


def drive_state_target(fmu, blob, t):
    c, errors = _continue_serialized(fmu, blob, t, lambda h: _run_drive(h, 700, 300))
    return {"c": c, "errors": errors}


def drive_errors(fmu):
    _host_package()
    r = _runner()
    res = {}
    with r.SlaveHandle.open(fmu, "bad") as h:
        # pre-torque above the torque limit: DriveParams.validate raises in initialize(), and
        # fmi2ExitInitializationMode returns its status
        from fmpy.fmi1 import FMICallException
        try:
            h.setup(0.0, start_values={"pretorque[1]": 5000.0})
            res["bad_param_init"] = 0
        except FMICallException as e:
            res["bad_param_init"] = e.status
        res["bad_param_msgs"] = _msgs(h)
    with r.SlaveHandle.open(fmu, "drive") as h:
        h.setup(0.0)
        res["ok"] = h.step(DT)
        mark = len(h.messages)
        h.set("motor.speed", float("nan"))
        res["nan_step"] = h.step(DT)
        res["nan_msgs"] = _msgs(h)[mark:]
        h.set("motor.speed", 0.0)
        res["recovered"] = h.step(DT)
    return res


# ---------------------------------------------------------------------------------------------- co-simulation
def _cols(res, names):
    return {n: [float(x) for x in res[n]] for n in names}


CMP = ["car.position", "car.velocity", "car.acceleration", "motor.speed", "motor.torque", "brake.command",
       "traction.tension_in", "traction.traction_ratio"]


def cosim_vs_monolithic(plant_fmu, drive_fmu, t_end, scheme, drive_values):
    """fmpy co-simulation of the FMUs against the same models coupled in-process at the same step."""
    pkg = _host_package()
    from reeve_fmu.fmu.cosim import cosimulate, monolithic

    c = cosimulate(plant_fmu, drive_fmu, step=DT, t_end=t_end, scheme=scheme, drive_values=drive_values)
    m = monolithic(step=DT, t_end=t_end, record_step=DT, scheme=scheme, drive_values=drive_values,
                   plant_fmu=plant_fmu)
    diffs = {n: float(max(abs(a - b) for a, b in zip(c[n], m[n]))) for n in CMP}
    return {"diffs": diffs, "n": [len(c.time), len(m.time)], "warnings": c.info["fmu_warnings"],
            "pkg": pkg.__file__, "x_end": float(c["car.position"][-1]),
            "brake_max": float(max(c["brake.command"]))}


def cosim_accuracy(plant_fmu, drive_fmu, steps, drive_values, ref_step=1e-4):
    """Full trip: FMU co-simulation at each communication step vs the monolithic reference."""
    _host_package()
    import numpy as np

    from reeve_fmu.fmu.cosim import cosimulate, monolithic

    ref = monolithic(step=ref_step, record_step=1e-3, drive_values=drive_values, plant_fmu=plant_fmu)
    out = {"ref_rtf": ref.info["rtf"], "t_end": float(ref.time[-1])}
    for h in steps:
        c = cosimulate(plant_fmu, drive_fmu, step=h, drive_values=drive_values)
        m = int(round(h / 1e-3))
        xr = ref["car.position"][::m][:len(c.time)]
        err = np.abs(c["car.position"] - xr)
        out[str(h)] = {"max_err_m": float(err.max()), "t_at_max": float(c.time[int(err.argmax())]),
                       "rtf": c.info["rtf"], "warnings": c.info["fmu_warnings"]}
    return out


def cosim_monitor(plant_fmu, drive_fmu, t_end, drive_values, steps):
    """fmpy master with the coupling monitor, on_instability="stop", at each step: what it reports
    (result fields, logged warning, FMU warnings) and where it stopped."""
    _host_package()
    import logging

    from reeve_fmu.fmu.cosim import MONITOR_FIELDS, cosimulate, monolithic

    logged = []

    class _H(logging.Handler):
        def emit(self, rec):
            logged.append((rec.levelname, rec.getMessage()))

    logging.getLogger("reeve_fmu.fmu.cosim").addHandler(_H())
    out = {}
    for h in steps:
        del logged[:]
        c = cosimulate(plant_fmu, drive_fmu, step=h, t_end=t_end, drive_values=drive_values,
                       on_instability="stop", record=["car.position"])
        out[str(h)] = {**{k: c.info[k] for k in MONITOR_FIELDS}, "logged": list(logged),
                       "stopped": c.info["stopped_by_monitor"], "t_last": float(c.time[-1]),
                       "steps": c.info["steps"], "fmu_warnings": c.info["fmu_warnings"],
                       "torque": [float(x) for x in c["motor.torque"]]}
        m = monolithic(step=h, t_end=t_end, record_step=h, drive_values=drive_values, plant_fmu=plant_fmu,
                       on_instability="stop")
        out[str(h)]["in_process"] = {k: m.info[k] for k in MONITOR_FIELDS}
    return out


def reference_error(results_csv, summary_json, ref_step=1e-4):
    """Monolithic reference (same plant scene, parameters and drive values as the demo, coupled every
    ref_step) against the car position of the demo's co-simulation (results.csv)."""
    _host_package()
    import json

    import numpy as np

    from reeve_fmu.fmu.cosim import monolithic

    with open(summary_json, encoding="utf-8") as fh:
        sc = json.load(fh)["scenario"]
    d = np.genfromtxt(results_csv, delimiter=",", names=True, deletechars="")
    # the exact parameter values the demo gave its FMUs (drive sized from the scene, pre-torques, landings)
    ref = monolithic(step=ref_step, t_end=sc["t_end_s"], record_step=sc["communication_step_s"],
                     plant_fmu=sc["plant_fmu"], plant_values=sc["plant_values"], drive_values=sc["drive_values"])
    n = min(len(ref.time), len(d["time"]))
    assert np.allclose(ref.time[:n], d["time"][:n], rtol=0, atol=1e-9)
    err = np.abs(d["car.position"][:n] - ref["car.position"][:n])
    k = int(np.argmax(err))
    return {"max_err_m": float(err[k]), "t_at_max": float(d["time"][k]), "n": n, "ref_rtf": ref.info["rtf"],
            "travel_m": float(np.max(d["car.position"]) - np.min(d["car.position"]))}


def fmpy_run(plant_fmu, drive_fmu, t_end, scheme, plant_values, drive_values, ns_step_differences=False):
    """fmpy master run (FMUs via their own package) for the comparison with libcosim."""
    _fmu_package(plant_fmu)
    from reeve_fmu.fmu.cosim import cosimulate

    c = cosimulate(plant_fmu, drive_fmu, step=DT, t_end=t_end, scheme=scheme, plant_values=plant_values,
                   drive_values=drive_values, ns_step_differences=ns_step_differences)
    return {"time": [float(x) for x in c.time], **_cols(c, CMP)}


def libcosim_run(ssp_dir, t_end):
    """libcosim runs the SSP (no reeve_fmu import in this process)."""
    spec = importlib.util.spec_from_file_location("run_libcosim", os.path.join(REPO, "cosim", "run_libcosim.py"))
    run_libcosim = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(run_libcosim)

    res = run_libcosim.run_ssp(ssp_dir, step=DT, t_end=t_end)
    assert "reeve_fmu" not in sys.modules or "reeve_fmu_vendor" not in sys.modules["reeve_fmu"].__file__
    return res


# ---------------------------------------------------------------------------------------------- fixture helper
def session_fmu_dir(tmp_path_factory):
    """Where the session's test FMUs live: under pytest-xdist one directory for all workers (the parent
    of the per-worker base temp), so the FMUs are built once per session, not once per worker."""
    base = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER") and fcntl is not None:
        base = base.parent
    return base / "reeve_cosim_fmus"


def ensure_test_fmus(base, timeout=600.0):
    """Build both FMUs with the CLI (`reeve-fmu build --dest base/fmus`) once per test session and copy
    the SSP next to them (base/cosim/ReevingSystem -> ../../fmus/*.fmu resolves to base/fmus). A file
    lock makes concurrent callers (pytest-xdist workers) wait for the one that builds (POSIX; without
    fcntl each worker uses its own directory anyway, see session_fmu_dir)."""
    import pathlib
    import subprocess

    base = pathlib.Path(base)
    base.mkdir(parents=True, exist_ok=True)
    marker = base / "built.ok"
    with open(base / ".lock", "w", encoding="utf-8") as lock:
        if fcntl is not None:
            fcntl.flock(lock, fcntl.LOCK_EX)
        if not marker.exists():
            fmus = base / "fmus"
            p = subprocess.run([sys.executable, "-m", "reeve_fmu.cli", "build", "--dest", str(fmus)],
                               cwd=REPO, capture_output=True, text=True, timeout=timeout)
            if p.returncode != 0:
                raise RuntimeError(f"reeve-fmu build failed ({p.returncode}):\n{p.stdout}\n{p.stderr}")
            ssp = base / "cosim" / "ReevingSystem"
            ssp.mkdir(parents=True, exist_ok=True)
            shutil.copy2(os.path.join(REPO, "cosim", "ReevingSystem", "SystemStructure.ssd"), ssp)
            marker.write_text(p.stdout, encoding="utf-8")
    return {"base": str(base), "plant": str(base / "fmus" / "ReevingPlant.fmu"),
            "drive": str(base / "fmus" / "ElectricDrive.fmu"), "ssp": str(base / "cosim" / "ReevingSystem"),
            "build_log": marker.read_text(encoding="utf-8")}


def cosim_stopped_run(plant_fmu, drive_fmu, drive_values):
    """A trip commanded beyond the top landing: the plant's step fails when a span vanishes; cosimulate
    raises CosimError carrying the result up to the last good communication point."""
    import numpy as np

    _fmu_package(plant_fmu)
    from reeve_fmu.fmu.cosim import cosimulate
    from reeve_fmu.fmu.master import CosimError

    try:
        cosimulate(plant_fmu, drive_fmu, step=DT, t_end=60.0, drive_values=drive_values)
    except CosimError as exc:
        r = exc.result
        return {"time": exc.time, "message": str(exc).splitlines()[0], "rows": int(len(r.time)),
                "t_last": float(r.time[-1]), "car_last": float(r.columns["car.position"][-1]),
                "finite": bool(all(np.isfinite(v).all() for v in r.columns.values()))}
    return {"time": None}


# ------------------------------------------------------------------------------------ loader fast path
def _linked_slaves():
    """The reeve_fmu slaves alive in this process (fmpy loads the FMUs in-process) and their links."""
    import gc

    gc.collect()      # instances dropped by fmi2Reset may sit in reference cycles
    return {o.instance_name: o._link for o in gc.get_objects()
            if any(c.__name__ == "ReeveSlave" for c in type(o).__mro__[1:])}


def fast_path_run(plant_fmu, drive_fmu, fast, steps=400):
    """The master's exchange through the FMUs' loaders with the fast path on (fast=1) or off (0):
    Gauss-Seidel steps over the R1 start (exchanged values every step, every output every 50 steps), a
    rewind of both FMUs by getFMUstate/setFMUstate, a rejected out-of-range input, a reset of the
    drive, and fmi2LastSuccessfulTime / fmi2Terminated of the plant."""
    import ctypes

    os.environ["REEVE_FMU_FAST_PATH"] = str(fast)
    _host_package()
    r = _runner()
    res = {"rows": [], "full": [], "status": []}
    values = {"pretorque[1]": 522.5, "pretorque[2]": 331.5, "trip.start_delay": 0.0}   # torque from t = 0
    with r.SlaveHandle.open(drive_fmu, "drive") as d, r.SlaveHandle.open(plant_fmu, "plant") as p:
        d.setup(0.0, start_values=values)
        p.setup(0.0)
        links = _linked_slaves()
        res["linked"] = {k: v is not None for k, v in links.items()}
        names_d = [v.name for v in d.md.modelVariables if v.causality == "output"]
        names_p = [v.name for v in p.md.modelVariables if v.causality == "output"]

        def gs_step(i):
            w, th = p.get_many(["motor.speed", "motor.angle"])
            d.set_many({"motor.speed": w, "motor.angle": th})
            sd = d.step(DT)
            tau, br = d.get_many(["motor.torque", "brake.command"])
            p.set_many({"motor.torque": tau, "brake.command": br})
            if i == 3 and links.get("plant") is not None:   # the value waits in the table, not in Python
                res["table_pending"] = (links["plant"].state[2], links["plant"].val[p.vr("motor.torque")] == tau)
            sp = p.step(DT)
            res["status"].append((sd, sp))
            res["rows"].append([w, th, tau, br])
            if i % 50 == 0:
                res["full"].append(d.get_many(names_d) + p.get_many(names_p))

        for i in range(steps // 2):
            gs_step(i)
        sd_, sp_, t_mark = d.get_state(), p.get_state(), p.time
        for i in range(steps // 2, steps):
            gs_step(i)
        d.set_state(sd_, time=t_mark)
        p.set_state(sp_, time=t_mark)
        res["rewound"] = []
        for i in range(steps // 2, steps):
            gs_step(i)
            res["rewound"].append(res["rows"].pop())
        mark = len(p.messages)
        p.set("brake.command", 2.0)
        res["rejected_step"] = p.step(DT)
        res["rejected_msgs"] = [m.message for m in p.messages[mark:] if m.status >= 3]
        p.set("brake.command", 1.0)
        res["after_rejected"] = p.step(DT)
        lst, term = ctypes.c_double(), ctypes.c_int()
        p.fmu.fmi2GetRealStatus(p.fmu.component, 2, ctypes.byref(lst))         # fmi2LastSuccessfulTime
        p.fmu.fmi2GetBooleanStatus(p.fmu.component, 3, ctypes.byref(term))     # fmi2Terminated
        res["last_successful_time"], res["terminated"] = lst.value, term.value
        res["plant_time"] = p.time
        d.reset()
        d.setup(0.0, start_values=values)
        res["relinked"] = _linked_slaves().get("drive") is not None
        d.set_many({"motor.speed": 0.0, "motor.angle": 0.0})
        res["after_reset"] = [d.step(DT), *d.get_many(["motor.torque", "brake.command"])]
        d.free_state(sd_)
        p.free_state(sp_)
    return res
