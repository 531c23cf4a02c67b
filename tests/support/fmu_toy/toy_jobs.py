"""Jobs for tests/fmu/test_fmu_machinery.py, each executed in a fresh interpreter by run_in_subprocess.

Jobs that load the FMU import the runner *by file path* (it has no reeve_fmu imports), so the host
process has not imported `reeve_fmu` and the FMU goes through its bootstrap shim, as it would under
any plain fmpy/libcosim host. Results travel as JSON (floats exactly).
"""
import importlib.util
import os
import shutil
import sys

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
TOY = os.path.join(REPO, "tests", "support", "fmu_toy", "reeve_toy_slave.py")
OUTS = ["sheave.phi", "sheave.w", "cabin.position", "cabin.velocity", "cabin.acceleration",
        "rope.tension", "rope.meanTension", "motor.power", "steps"]
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


def _import_snapshot(snap_dir):
    """Import the package snapshot in snap_dir as `reeve_fmu` (later imports of reeve_fmu get it)."""
    pkg = os.path.join(snap_dir, "reeve_fmu")
    spec = importlib.util.spec_from_file_location("reeve_fmu", os.path.join(pkg, "__init__.py"),
                                                  submodule_search_locations=[pkg])
    reeve_fmu = importlib.util.module_from_spec(spec)
    sys.modules["reeve_fmu"] = reeve_fmu
    spec.loader.exec_module(reeve_fmu)

    assert os.path.dirname(os.path.dirname(os.path.abspath(reeve_fmu.__file__))) == \
        os.path.abspath(snap_dir), reeve_fmu.__file__
    return reeve_fmu


def _tau(i):
    """Deterministic torque schedule around the holding torque 500*9.81*0.3 = 1471.5 N.m."""
    return 1471.5 + (150.0 if (i // 25) % 2 == 0 else -120.0) + 0.5 * i


def _run(h, i0, n, c_change_at=None):
    out = []
    for i in range(i0, i0 + n):
        if c_change_at is not None and i == c_change_at:
            h.set("rope.c", 3500.0)
        h.set("motor.tau", _tau(i))
        st = h.step(DT)
        if st != 0:
            raise RuntimeError(f"step {i} returned status {st}:\n{h.log_text()}")
        out.append(h.get_many(OUTS))
    return out


# ---------------------------------------------------------------------------------------------- build
def build(snap_dir, out_dir, scene_text):
    _import_snapshot(snap_dir)
    from reeve_fmu.fmu.build import build_fmu, read_stamp

    path = build_fmu(TOY, out_dir, resources={"scene.toml": scene_text.encode()})
    return {"path": str(path), "stamp": read_stamp(path), "modules": sorted(
        m for m in sys.modules if m.startswith("reeve_toy"))}


# ---------------------------------------------------------------------------------------------- state
def rewind(fmu):
    r = _runner()
    assert "reeve_fmu" not in sys.modules
    with r.SlaveHandle.open(fmu, "toy") as h:
        h.setup(0.0, 2.0)
        _run(h, 0, 40)
        t_snap = h.time
        snap_out = h.get_many(OUTS)
        s = h.get_state()
        a = _run(h, 40, 60, c_change_at=50)
        h.set_state(s, time=t_snap)
        restored_out = h.get_many(OUTS)
        restored_c = h.get("rope.c")
        b = _run(h, 40, 60, c_change_at=50)
        h.set_state(s, time=t_snap)          # the same state object can be restored again
        c = _run(h, 40, 60, c_change_at=50)
        h.free_state(s)
        import reeve_fmu

        return {"a": a, "b": b, "c": c, "snap_out": snap_out, "restored_out": restored_out,
                "restored_c": restored_c, "errors": [str(m) for m in h.errors()],
                "pkg_file": reeve_fmu.__file__}


def serialize_source(fmu):
    """Instance 1: run 40 steps, serialize; continue 60 steps (reference)."""
    r = _runner()
    with r.SlaveHandle.open(fmu, "src") as h:
        h.setup(0.0, 2.0)
        _run(h, 0, 40)
        t = h.time
        s = h.get_state()
        blob = h.serialize_state(s)
        h.free_state(s)
        ref = _run(h, 40, 60, c_change_at=50)
        # in-process: a second, fresh instance (shares the extracted directory) restores the blob
        same_proc = {}
        for label, init, mass in (("initialized_other_params", True, 800.0),
                                  ("never_initialized", False, None)):
            with r.SlaveHandle.open(fmu, f"dst_{label}", unzip_dir=h.unzip_dir) as g:
                if init:
                    g.setup(0.0, 2.0, start_values={"cabin.mass": mass})
                st = g.deserialize_state(blob)
                g.set_state(st, time=t)
                g.free_state(st)
                same_proc[label] = {"cont": _run(g, 40, 60, c_change_at=50),
                                    "mass": g.get("cabin.mass"),
                                    "errors": [str(m) for m in g.errors()]}
        return {"blob": blob.decode("latin-1"), "t": t, "ref": ref, "same_proc": same_proc,
                "size": len(blob), "errors": [str(m) for m in h.errors()]}


def serialize_target(fmu, blob, t):
    """Another process: new instance, deserialize, continue."""
    r = _runner()
    with r.SlaveHandle.open(fmu, "dst") as h:
        h.setup(0.0, 2.0)
        st = h.deserialize_state(blob.encode("latin-1"))
        h.set_state(st, time=t)
        h.free_state(st)
        return {"cont": _run(h, 40, 60, c_change_at=50), "errors": [str(m) for m in h.errors()]}


# ---------------------------------------------------------------------------------------------- errors
def exception_in_step(fmu):
    r = _runner()
    with r.SlaveHandle.open(fmu, "toy") as h:
        h.setup(0.0, 2.0)
        _run(h, 0, 5)
        t_snap, s = h.time, h.get_state()
        h.set("test.raiseInStep", True)
        st_raise = h.step(DT)
        n_after_raise = len(h.messages)
        h.set("test.raiseInStep", False)
        st_dirty = h.step(DT)                # refused: state may be inconsistent
        h.set_state(s, time=t_snap)          # rollback makes it usable again
        h.set("test.raiseInStep", False)
        st_after_restore = h.step(DT)
        return {"st_raise": st_raise, "st_dirty": st_dirty, "st_after_restore": st_after_restore,
                "raise_msgs": [(m.status, m.message) for m in h.messages[:n_after_raise]],
                "later_msgs": [(m.status, m.message) for m in h.messages[n_after_raise:]]}


def invalid_calls(fmu):
    r = _runner()
    res = {}
    with r.SlaveHandle.open(fmu, "early") as h:
        res["before_init"] = h.do_step(0.0, DT)
        h.fmu.setupExperiment(startTime=0.0)
        h.fmu.enterInitializationMode()
        res["in_init"] = h.do_step(0.0, DT)
        h.set("cabin.mass", 0.0)             # below min=1: rejected, step refused until fixed
        h.fmu.exitInitializationMode()
        h._initialized = True
        h.time = 0.0
        res["bad_param_step"] = h.step(DT)
        res["early_msgs"] = [(m.status, m.message) for m in h.messages]

    with r.SlaveHandle.open(fmu, "toy") as h:
        h.setup(0.0, 2.0)
        h.set("motor.tau", 1500.0)
        res["ok0"] = h.step(DT)
        marks = {}

        def mark(key):
            marks[key] = len(h.messages)

        mark("nan")
        h.set("motor.tau", float("nan"))
        res["nan_value_kept"] = h.get("motor.tau")
        res["nan_step"] = h.step(DT)
        res["nan_step_again"] = h.step(DT)
        mark("inf")
        h.set("motor.tau", float("-inf"))
        res["inf_step"] = h.step(DT)
        h.set("motor.tau", 1500.0)
        res["recovered"] = h.step(DT)
        mark("dt")
        res["dt_zero"] = h.do_step(h.time, 0.0)
        res["dt_neg"] = h.do_step(h.time, -DT)
        res["dt_nan"] = h.do_step(h.time, float("nan"))
        res["dt_inf"] = h.do_step(h.time, float("inf"))
        mark("jump")
        res["time_jump"] = h.do_step(h.time + 0.5, DT)
        mark("fixed")
        h.set("cabin.mass", 900.0)
        res["fixed_step"] = h.step(DT)
        res["fixed_value"] = h.get("cabin.mass")
        res["after_fixed"] = h.step(DT)
        mark("end")
        res["ok_end"] = h.step(DT)
        msgs = [(m.status, m.message) for m in h.messages]
        keys = list(marks)
        res["msgs"] = {k: msgs[marks[k]:(marks[keys[i + 1]] if i + 1 < len(keys) else None)]
                       for i, k in enumerate(keys)}
    return res


# ---------------------------------------------------------------------------------------------- reset
def reset(fmu):
    r = _runner()
    with r.SlaveHandle.open(fmu, "toy") as h:
        h.setup(0.0, 2.0)
        a = _run(h, 0, 80, c_change_at=30)
        h.set("test.raiseInStep", True)
        h.step(DT)                            # leave the instance dirty before the reset
        h.terminate()
        h.reset()
        after_reset = {"rope.c": h.get("rope.c"), "steps": h.get("steps"),
                       "motor.tau": h.get("motor.tau"), "test.raiseInStep": h.get("test.raiseInStep")}
        h._terminated = False
        h.setup(0.0, 2.0)
        b = _run(h, 0, 80, c_change_at=30)
        return {"a": a, "b": b, "after_reset": after_reset, "errors_after_reset": [
            str(m) for m in h.messages if m.status >= 3 and "raised" not in m.message
            and "toy failure" not in m.message]}


# ---------------------------------------------------------------------------------------------- stale
def stale(snap_dir, work_dir, fmu, scene_text):
    snap2 = os.path.join(work_dir, "snap2")
    shutil.copytree(snap_dir, snap2, ignore=shutil.ignore_patterns("__pycache__"))
    _import_snapshot(snap2)
    from reeve_fmu.fmu.build import current_package_hash, fmu_is_stale, read_stamp

    res = {"hash_equal": read_stamp(fmu)["sha256"] == current_package_hash()}
    res["fresh"] = fmu_is_stale(fmu)
    res["fresh_with_inputs"] = fmu_is_stale(fmu, entry_script=TOY,
                                            resources={"scene.toml": scene_text.encode()})
    res["resource_changed"] = fmu_is_stale(fmu, resources={"scene.toml": b"other = 2\n"})
    toy2 = os.path.join(work_dir, "reeve_toy_slave.py")
    with open(TOY, encoding="utf-8") as fh, open(toy2, "w", encoding="utf-8") as out:
        out.write(fh.read() + "\n# edited\n")
    res["entry_changed"] = fmu_is_stale(fmu, entry_script=toy2)
    res["missing"] = fmu_is_stale(os.path.join(work_dir, "nope.fmu"))
    with open(os.path.join(snap2, "reeve_fmu", "fmu", "jitcheck.py"), "a", encoding="utf-8") as fh:
        fh.write("\n# edited\n")
    res["package_changed"] = fmu_is_stale(fmu)
    os.unlink(os.path.join(snap2, "reeve_fmu", "fmu", "jitcheck.py"))
    res["package_file_removed"] = fmu_is_stale(fmu)
    return res


# ---------------------------------------------------------------------------------------------- cache
def cache_run(fmu):
    """Plain host (no reeve_fmu imported): the shim must serve the package from the cache dir."""
    r = _runner()
    assert "reeve_fmu" not in sys.modules
    with r.SlaveHandle.open(fmu, "toy") as h:
        h.setup(0.0, 1.0)
        st = h.step(DT)
        import reeve_fmu
        from reeve_fmu.fmu.jitcheck import jit_cache_probe

        init_py = reeve_fmu.__file__
        return {"status": st, "pkg_file": init_py, "boot": reeve_fmu._reeve_fmu_boot,
                "mtime_ns": os.stat(init_py).st_mtime_ns, "probe": jit_cache_probe(),
                "resources": h.unzip_dir, "msgs": [str(m) for m in h.messages]}


def host_imported(snap_dir, work_dir, fmu):
    """Host imported reeve_fmu first: same sources -> silent reuse; other sources -> warning."""
    reeve_fmu = _import_snapshot(snap_dir)
    r = _runner()
    res = {}
    with r.SlaveHandle.open(fmu, "same") as h:
        h.setup(0.0, 1.0)
        res["same_status"] = h.step(DT)
        res["same_msgs"] = [str(m) for m in h.messages]
    res["same_pkg_file"] = reeve_fmu.__file__
    return res


def host_imported_other(snap_dir, work_dir, fmu):
    snap3 = os.path.join(work_dir, "snap3")
    shutil.copytree(snap_dir, snap3, ignore=shutil.ignore_patterns("__pycache__"))
    with open(os.path.join(snap3, "reeve_fmu", "zz_local_edit.py"), "w", encoding="utf-8") as fh:
        fh.write("# a local edit that the FMU does not carry\n")
    reeve_fmu = _import_snapshot(snap3)
    r = _runner()
    with r.SlaveHandle.open(fmu, "other") as h:
        h.setup(0.0, 1.0)
        st = h.step(DT)
        return {"status": st, "msgs": [(m.status, m.message) for m in h.messages],
                "pkg_file": reeve_fmu.__file__}


# ---------------------------------------------------------------------------------------------- fmpy
def simulate(fmu):
    """Plain fmpy.simulate_fmu (its own loop, validation and logger) on the FMU."""
    import numpy as np
    from fmpy import simulate_fmu

    msgs = []

    def logger(*args):
        msgs.append(args[-1].decode() if isinstance(args[-1], bytes) else str(args[-1]))

    inp = np.array([(0.0, 1600.0), (0.05, 1600.0), (0.05, 1400.0), (0.1, 1400.0)],
                   dtype=[("time", "f8"), ("motor.tau", "f8")])
    res = simulate_fmu(fmu, stop_time=0.1, output_interval=1e-3, input=inp,
                       output=["cabin.position", "steps"], start_values={"rope.c": 2500.0},
                       debug_logging=True, logger=logger)
    return {"n": len(res), "steps": int(res["steps"][-1]), "x_end": float(res["cabin.position"][-1]),
            "errors": [m for m in msgs if "rror" in m]}


def broken_import(fmu):
    """An FMU whose entry fails to import: the cause must reach the caller, no crash."""
    r = _runner()
    try:
        r.SlaveHandle.open(fmu, "broken")
    except RuntimeError as exc:
        return {"raised": True, "text": str(exc)}
    return {"raised": False, "text": ""}
