"""Tests of the generic FMU machinery: ReeveSlave, build_fmu/fmu_is_stale, run_in_subprocess/SlaveHandle.

The toy FMU (tests/support/fmu_toy/reeve_toy_slave.py) is built once per module from a *snapshot* of the
package (other engineers edit reeve_fmu/ concurrently; a snapshot keeps the source hash stable for
the stale/hash tests). Every FMU-loading check runs in its own fresh interpreter (docs/cosim.md, 'pythonfmu and fmpy' item 4); the
job functions live in tests/support/fmu_toy/toy_jobs.py.
"""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

import pytest

from reeve_fmu.fmu._bootstrap import copy_package, package_hash
from reeve_fmu.fmu.runner import SubprocessJobError, run_in_subprocess
from reeve_fmu.core._jit import JIT as _JIT  # the compiled-kernel cache tests need numba
from tests.support import ROOT

JOBS = str(ROOT / "tests" / "support" / "fmu_toy" / "toy_jobs.py")
SCENE = "# toy scene\nmass = 500.0\n"


def job(name, *args, cache=None, timeout=900.0):
    env = dict(os.environ)
    env["REEVE_FMU_CACHE_DIR"] = str(cache)
    return run_in_subprocess(f"{JOBS}:{name}", *args, env=env, timeout=timeout)


@pytest.fixture(scope="module")
def toy(tmp_path_factory):
    base = tmp_path_factory.mktemp("fmu_machinery")
    snap = base / "snap"
    copy_package(str(ROOT / "reeve_fmu"), str(snap / "reeve_fmu"))
    cache = base / "cache"
    res = job("build", str(snap), str(base / "out"), SCENE, cache=cache)
    return {"fmu": res["path"], "stamp": res["stamp"], "snap": str(snap), "base": base,
            "cache": cache, "hash": package_hash(str(snap / "reeve_fmu"))}


# ------------------------------------------------------------------------------------------------
# build + modelDescription
# ------------------------------------------------------------------------------------------------
def test_fmpy_validate_cli_reports_no_problems(toy):
    p = subprocess.run([sys.executable, "-m", "fmpy", "validate", toy["fmu"]],
                       capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stdout + p.stderr
    assert "No problems found" in p.stdout


def test_model_description_units_structure_and_resources(toy):
    with zipfile.ZipFile(toy["fmu"]) as zf:
        names = set(zf.namelist())
        xml = ET.fromstring(zf.read("modelDescription.xml"))
        stamp = json.loads(zf.read("resources/reeve_fmu_stamp.json"))
        reqs = zf.read("resources/requirements.txt").decode()
        scene = zf.read("resources/scene.toml").decode()
    # vendored package behind the shim, no caches, stamp/requirements/resources present
    assert "resources/reeve_fmu.py" in names
    assert "resources/reeve_fmu_vendor/reeve_fmu/fmu/slave.py" in names
    assert not any("__pycache__" in n or n.endswith((".pyc", ".nbi", ".nbc")) for n in names)
    assert stamp["sha256"] == toy["hash"] and stamp["entry"]["name"] == "reeve_toy_slave.py"
    assert "numpy>=1.24" in reqs and "scipy>=1.10" in reqs and scene == SCENE   # what the model imports ...
    assert "matplotlib" not in reqs and "fmpy" not in reqs                       # ... and nothing else
    assert "tomli>=2.0; python_version < '3.11'" in reqs
    # capability flags
    cs = xml.find("CoSimulation").attrib
    assert cs["canGetAndSetFMUstate"] == "true" and cs["canSerializeFMUstate"] == "true"
    assert cs["canInterpolateInputs"] == "false"
    # units with base-unit exponents and display units
    units = {u.get("name"): u for u in xml.find("UnitDefinitions")}
    assert units["N.m"].find("BaseUnit").attrib == {"kg": "1", "m": "2", "s": "-2"}
    rpm = {d.get("name"): float(d.get("factor")) for d in units["rad/s"].findall("DisplayUnit")}
    assert rpm["rpm"] == pytest.approx(60 / (2 * math.pi))
    assert xml.find("TypeDefinitions/SimpleType[@name='Position']/Real").get("unit") == "m"
    de = xml.find("DefaultExperiment").attrib
    assert (float(de["startTime"]), float(de["stopTime"]), float(de["stepSize"])) == (0.0, 2.0, 1e-3)
    sv = {v.get("name"): (i + 1, v) for i, v in enumerate(xml.find("ModelVariables"))}
    assert sv["steps"][1].get("variability") == "discrete"
    assert sv["test.raiseInStep"][1].get("variability") == "discrete"
    assert sv["sheave.w"][1].find("Real").get("derivative") == str(sv["sheave.phi"][0])
    assert sv["sheave.w"][1].find("Real").get("displayUnit") == "rpm"
    # ModelStructure: explicit dependencies, feed-through only where declared
    deps = {int(u.get("index")): u.get("dependencies")
            for u in xml.find("ModelStructure/Outputs")}
    assert deps[sv["motor.power"][0]] == str(sv["motor.tau"][0])
    assert deps[sv["cabin.position"][0]] == "" and deps[sv["rope.tension"][0]] == ""
    outputs = {i for i, v in sv.values() if v.get("causality") == "output"}
    assert set(deps) == outputs
    initial = {int(u.get("index")) for u in xml.find("ModelStructure/InitialUnknowns")}
    assert initial == outputs


def test_plain_fmpy_simulate_fmu_runs_the_fmu(toy):
    r = job("simulate", toy["fmu"], cache=toy["cache"])
    assert r["errors"] == [] and r["steps"] == 100 and r["n"] == 101
    assert math.isfinite(r["x_end"])


def test_build_refuses_generic_entry_names_and_broken_definitions(tmp_path):
    """In-process: these fail before any FMU binary is loaded."""
    from reeve_fmu.fmu.build import FmuBuildError, build_fmu

    generic = tmp_path / "model.py"
    generic.write_text("x = 1\n", encoding="utf-8")
    with pytest.raises(FmuBuildError, match="too generic"):
        build_fmu(generic, tmp_path / "out")
    body = ("from reeve_fmu.fmu.slave import ReeveSlave\n"
            "class {cls}(ReeveSlave):\n"
            "    def define(self):\n"
            "        self.add_real('u', 'input', unit='N', start=0.0)\n"
            "        {line}\n"
            "    def step(self, t, dt):\n"
            "        return True\n")
    cases = {
        "reeve_badunit_probe": ("self.add_real('y', 'output', unit='furlong')", "unknown unit 'furlong'"),
        "reeve_baddep_probe": ("self.add_real('y', 'output', unit='N', dependencies=['nope'])",
                               "dependency 'nope' is not an input"),
        "reeve_badint_probe": ("self.add_integer('n', 'output', 'continuous')",
                               "cannot be continuous"),
        # passes our checks, caught by the fmpy validation gate
        "reeve_badname_probe": ("self.add_real('bad name!', 'output', unit='N')",
                                "not a legal variable name"),
    }
    out = tmp_path / "out"
    out.mkdir()
    (out / "ReeveBadnameProbe.fmu").write_bytes(b"previous good build")
    for stem, (line, err) in cases.items():
        src = tmp_path / f"{stem}.py"
        src.write_text(body.format(cls=stem.title().replace("_", ""), line=line), encoding="utf-8")
        with pytest.raises(FmuBuildError, match=err):
            build_fmu(src, out)
        assert stem not in sys.modules and str(tmp_path) not in sys.path
    # failed builds leave nothing behind and never clobber an existing FMU
    assert [p.name for p in out.iterdir()] == ["ReeveBadnameProbe.fmu"]
    assert (out / "ReeveBadnameProbe.fmu").read_bytes() == b"previous good build"


PROBE = ("from reeve_fmu.fmu.slave import ReeveSlave\n"
         "class ReevePendingProbe(ReeveSlave):\n"
         "    def define(self):\n"
         "        self.add_real('u', 'input', unit='N', start=0.0)\n"
         "        self.add_real('y', 'output', unit='N')\n"
         "    def step(self, t, dt):\n"
         "        return True\n")


def test_a_pending_build_is_usable_and_replaces_the_destination_only_when_finished(tmp_path, monkeypatch):
    """start_fmu_build (what the demo co-simulates before the FMUs' kernels are collected): the FMU is
    valid at once in a private directory, the destination keeps its previous FMU until finish() has
    added what travels with the FMU and moved it into place; discard() drops a pending build."""
    from reeve_fmu.fmu import build

    carried = []
    monkeypatch.setattr(build, "_carry", lambda path, reqs, **kw: carried.append(
        (path, zipfile.is_zipfile(path), (out / "ReevePendingProbe.fmu").read_bytes())))
    src = tmp_path / "reeve_pending_probe.py"
    src.write_text(PROBE, encoding="utf-8")
    out = tmp_path / "out"
    out.mkdir()
    (out / "ReevePendingProbe.fmu").write_bytes(b"previous build")
    pending = build.start_fmu_build(src, out, native_loader=False)   # the loader plays no part here
    assert pending.path.is_file() and pending.path.parent.parent == out
    with zipfile.ZipFile(pending.path) as zf:
        assert "modelDescription.xml" in zf.namelist()
    assert (out / "ReevePendingProbe.fmu").read_bytes() == b"previous build" and carried == []
    final = pending.finish()
    assert carried == [(pending.path, True, b"previous build")]       # carried before the move
    assert final == out / "ReevePendingProbe.fmu" and zipfile.is_zipfile(final)
    assert [p.name for p in out.iterdir()] == ["ReevePendingProbe.fmu"]   # the private directory is gone
    assert pending.finish() == final and len(carried) == 1               # finish() is idempotent
    dropped = build.start_fmu_build(src, out, native_loader=False)
    dropped.discard()
    assert [p.name for p in out.iterdir()] == ["ReevePendingProbe.fmu"] and carried[1:] == []


# ------------------------------------------------------------------------------------------------
# FMU state
# ------------------------------------------------------------------------------------------------
def test_get_set_state_rewinds_bit_identically(toy):
    r = job("rewind", toy["fmu"], cache=toy["cache"])
    assert r["errors"] == []
    assert "reeve_fmu_vendor" not in r["pkg_file"] and str(toy["cache"]) in r["pkg_file"]
    assert r["a"] == r["b"] == r["c"]                       # exact float equality, 60 steps
    assert r["restored_out"] == r["snap_out"]
    assert r["restored_c"] == 2000.0                        # tunable change after the snapshot undone
    # the hidden integrator matters: rope.meanTension depends on it, and it moved during the run
    assert r["a"][-1][6] != r["snap_out"][6]


def test_serialize_to_new_instance_and_new_process(toy):
    src = job("serialize_source", toy["fmu"], cache=toy["cache"])
    assert src["errors"] == []
    for label, d in src["same_proc"].items():
        assert d["errors"] == [], (label, d["errors"])
        assert d["cont"] == src["ref"], label
        assert d["mass"] == 500.0, label                    # fixed parameters come with the state
    dst = job("serialize_target", toy["fmu"], src["blob"], src["t"], cache=toy["cache"])
    assert dst["errors"] == []
    assert dst["cont"] == src["ref"]


def test_state_json_roundtrip_is_exact():
    """In-process (no FMU): canonical copy + JSON serialization preserve every float bit."""
    import random
    import struct

    import numpy as np

    from reeve_fmu.fmu.slave import ReeveSlave
    from reeve_fmu.fmu.state import canonical_state

    rnd = random.Random(7)
    floats = [struct.unpack("<d", struct.pack("<Q", rnd.getrandbits(64)))[0] for _ in range(2000)]
    floats += [0.0, -0.0, 5e-324, -5e-324, 2.2250738585072014e-308, 1.7976931348623157e308,
               0.1, 1 / 3, math.pi, math.inf, -math.inf, math.nan]
    hidden = {"y": np.array(floats[:50]), "vals": floats, "n": 2 ** 70, "flag": True,
              "nested": {"t": (1.5, [np.float64(2.5)])}, "none": None, "s": "x%y"}
    state = canonical_state(hidden)
    back = ReeveSlave._fmu_state_from_bytes(ReeveSlave._fmu_state_to_bytes(state))

    def bits(x):
        return struct.pack("<d", x) if isinstance(x, float) and not math.isnan(x) else repr(x)

    assert [bits(x) for x in back["vals"]] == [bits(x) for x in floats]
    assert [bits(x) for x in back["y"]] == [bits(x) for x in floats[:50]]
    assert back["n"] == 2 ** 70 and back["flag"] is True and back["none"] is None
    assert back["nested"] == {"t": [1.5, [2.5]]} == state["nested"]
    assert math.isnan(back["vals"][-1])
    with pytest.raises(TypeError, match="dict key"):
        canonical_state({1: 2.0})
    with pytest.raises(TypeError, match="not allowed"):
        canonical_state({"obj": object()})


# ------------------------------------------------------------------------------------------------
# error handling
# ------------------------------------------------------------------------------------------------
def test_exception_in_step_is_logged_with_traceback_and_discarded(toy):
    r = job("exception_in_step", toy["fmu"], cache=toy["cache"])
    assert r["st_raise"] == 2                                # fmi2Discard, not fatal
    text = "\n".join(m for s, m in r["raise_msgs"] if s == 3)
    assert "Traceback (most recent call last)" in text
    assert "ZeroDivisionError: toy failure injected" in text
    assert "(100% intended, %s %d %n stay literal)" in text   # printf-escaped for the C logger
    assert "reeve_toy_slave.py" in text
    assert r["st_dirty"] == 2
    assert any("previous step raised" in m for s, m in r["later_msgs"] if s == 3)
    assert r["st_after_restore"] == 0


def test_invalid_inputs_and_calls_are_rejected_with_reason(toy):
    r = job("invalid_calls", toy["fmu"], cache=toy["cache"])
    early = "\n".join(m for _, m in r["early_msgs"])
    assert r["before_init"] == 2 and "refused in state 'instantiated'" in early
    assert r["in_init"] == 2 and "refused in state 'init'" in early
    assert r["bad_param_step"] == 2 and "cabin.mass = 0.0 is outside [1.0, None]" in early
    assert r["ok0"] == 0
    nan = "\n".join(m for _, m in r["msgs"]["nan"])
    assert r["nan_step"] == 2 and r["nan_step_again"] == 2
    assert "motor.tau = nan is not finite" in nan and r["nan_value_kept"] == 1500.0
    assert "invalid inputs were rejected" in nan
    assert r["inf_step"] == 2 and "-inf is not finite" in "\n".join(m for _, m in r["msgs"]["inf"])
    assert r["recovered"] == 0
    dt = "\n".join(m for _, m in r["msgs"]["dt"])
    assert (r["dt_zero"], r["dt_neg"], r["dt_nan"], r["dt_inf"]) == (2, 2, 2, 2)
    for s in ("communicationStepSize=0.0", "communicationStepSize=-0.001",
              "communicationStepSize=nan", "communicationStepSize=inf"):
        assert s in dt
    assert r["time_jump"] == 2 and "steps must be contiguous" in "\n".join(
        m for _, m in r["msgs"]["jump"])
    fixed = "\n".join(m for _, m in r["msgs"]["fixed"])
    assert "cabin.mass is a fixed parameter" in fixed
    assert r["fixed_step"] == 2 and r["fixed_value"] == 500.0 and r["after_fixed"] == 0
    assert r["ok_end"] == 0 and r["msgs"]["end"] == []      # no logging in normal steps
    assert all(s == 3 for k, ms in r["msgs"].items() for s, _ in ms)


def test_instantiate_failure_reports_the_cause(toy, tmp_path):
    broken = tmp_path / "ReeveToySlave.fmu"
    with zipfile.ZipFile(toy["fmu"]) as zin, zipfile.ZipFile(broken, "w") as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename == "resources/reeve_toy_slave.py":
                data = b"import reeve_missing_dependency_xyz\n" + data
            zout.writestr(item, data)
    r = job("broken_import", str(broken), cache=toy["cache"])
    assert r["raised"] is True
    assert "Failed to instantiate" in r["text"]
    assert "No module named 'reeve_missing_dependency_xyz'" in r["text"]


def test_reset_returns_to_initial_behaviour(toy):
    r = job("reset", toy["fmu"], cache=toy["cache"])
    assert r["after_reset"] == {"rope.c": 2000.0, "steps": 0, "motor.tau": 0.0,
                                "test.raiseInStep": False}
    assert r["a"] == r["b"]
    assert r["errors_after_reset"] == []


# ------------------------------------------------------------------------------------------------
# staleness, package cache, host-imported package
# ------------------------------------------------------------------------------------------------
def test_stale_check(toy):
    r = job("stale", toy["snap"], str(toy["base"] / "stale"), toy["fmu"], SCENE, cache=toy["cache"])
    assert r["hash_equal"] is True
    assert r["fresh"] is False and r["fresh_with_inputs"] is False
    assert r["resource_changed"] is True and r["entry_changed"] is True
    assert r["missing"] is True
    assert r["package_changed"] is True and r["package_file_removed"] is True


def test_package_served_from_stable_cache_and_numba_cache_hits(toy, tmp_path):
    cache = tmp_path / "cache"
    r1 = job("cache_run", toy["fmu"], cache=cache)
    r2 = job("cache_run", toy["fmu"], cache=cache)
    expect = cache / toy["hash"][:16] / "reeve_fmu" / "__init__.py"
    for r in (r1, r2):
        assert r["status"] == 0 and r["msgs"] == []
        assert Path(r["pkg_file"]) == expect
        assert r["boot"]["hash"] == toy["hash"] and r["boot"]["warning"] is None
    assert r1["resources"] != r2["resources"]              # fresh extraction each run ...
    assert r1["mtime_ns"] == r2["mtime_ns"]                # ... but the same package copy
    if r1["probe"]["jit"]:
        assert r1["probe"]["cache_misses"] == 1 and r1["probe"]["cache_hits"] == 0
        assert r2["probe"]["cache_hits"] == 1 and r2["probe"]["cache_misses"] == 0
        assert str(cache) in r2["probe"]["cache_path"]


@pytest.mark.skipif(not _JIT, reason="REEVE_FMU_NO_JIT=1 or numba not installed: the kernels run as plain Python and there is no compiled-kernel cache to test")
def test_fmu_package_copy_loads_the_kernels_its_source_compiled(toy, tmp_path):
    """numba's cache is keyed by the path inside the package and the file content, not by where the
    copy lives: kernels compiled by the package loaded from its snapshot directory are loaded, not
    compiled again, by the FMU's copy of the same sources (in <cache>/<hash>/reeve_fmu)."""
    cache = tmp_path / "cache"
    code = "import json; from reeve_fmu.fmu.jitcheck import jit_cache_probe as p; print(json.dumps(p()))"
    env = dict(os.environ, REEVE_FMU_CACHE_DIR=str(cache), PYTHONPATH=toy["snap"])
    p = subprocess.run([sys.executable, "-c", code], cwd=toy["snap"], env=env, capture_output=True,
                       text=True, timeout=600)
    assert p.returncode == 0, p.stderr
    direct = json.loads(p.stdout)
    assert direct["module_file"].startswith(toy["snap"])
    assert direct["jit"]
    assert direct["cache_misses"] == 1 and direct["cache_hits"] == 0          # compiled here
    r = job("cache_run", toy["fmu"], cache=cache)
    assert r["status"] == 0 and str(cache) in r["pkg_file"]                   # another copy ...
    assert r["probe"]["cache_hits"] == 1 and r["probe"]["cache_misses"] == 0  # ... no compile


def test_host_that_already_imported_reeve_fmu(toy):
    r = job("host_imported", toy["snap"], str(toy["base"]), toy["fmu"], cache=toy["cache"])
    assert r["same_status"] == 0 and r["same_msgs"] == []
    assert r["same_pkg_file"].startswith(toy["snap"])
    o = job("host_imported_other", toy["snap"], str(toy["base"]), toy["fmu"], cache=toy["cache"])
    assert o["status"] == 0                                  # still runs, but says so loudly
    warn = [m for s, m in o["msgs"] if s == 1]
    assert any("reeve_fmu version mismatch" in m and toy["hash"][:16] in m for m in warn), o["msgs"]


# ------------------------------------------------------------------------------------------------
# run_in_subprocess semantics (no FMU)
# ------------------------------------------------------------------------------------------------
def test_a_jobs_temporary_files_go_with_it(tmp_path):
    """A job ends without interpreter finalisation (os._exit), so what it unpacked into the temporary
    directory (fmpy.extract: ~5 MB per FMU) would stay: the job's temporary directory is inside its
    working directory, removed with it, also after a crash; a TMPDIR the caller sets is kept."""
    code = ("import os, tempfile\n"
            "d = tempfile.mkdtemp()\n"
            "open(os.path.join(d, 'unpacked'), 'w').close()\n"
            "result = d\n")
    left = run_in_subprocess(code)
    assert os.path.isabs(left) and not os.path.exists(left), left
    crashed = tmp_path / "crashed"
    with pytest.raises(SubprocessJobError, match="without writing its result"):
        run_in_subprocess(f"import os, tempfile; open({str(crashed)!r}, 'w').write(tempfile.mkdtemp()); os.abort()")
    assert not os.path.exists(crashed.read_text())
    own = tmp_path / "own"
    own.mkdir()
    kept = run_in_subprocess(code, env=dict(os.environ, TMPDIR=str(own)))
    assert os.path.dirname(kept) == str(own) and os.path.exists(os.path.join(kept, "unpacked"))


def test_run_in_subprocess_results_errors_and_exit_aborts(tmp_path):
    assert run_in_subprocess("result = [ARGS[0] * 2, float('nan') != float('nan')]", 21) == [42, True]
    assert run_in_subprocess("os.path:join", "a", "b") == os.path.join("a", "b")
    with pytest.raises(SubprocessJobError, match="ValueError: boom"):
        run_in_subprocess("raise ValueError('boom')")
    with pytest.raises(SubprocessJobError, match="without writing its result"):
        run_in_subprocess("import os; os.abort()")
    # interpreter finalisation is skipped once the result is written (os._exit), so an atexit handler
    # that would abort (in real life pythonfmu's heap corruption, docs/cosim.md, 'pythonfmu and fmpy'
    # item 4) never runs
    code = ("import atexit, os\n"
            "atexit.register(os.abort)\n"
            "result = 'fine'\n")
    assert run_in_subprocess(code) == "fine"
    # a crash after the result is on disk (here: the child's final os._exit aborts) fails the job, once:
    # a second, lucky run would hide it. The marker file counts the runs.
    marker = tmp_path / "runs"
    code = ("import os\n"
            "with open(ARGS[0], 'a') as fh: fh.write('x')\n"
            "os._exit = lambda code: os.abort()\n"
            "result = 'written'\n")
    with pytest.raises(SubprocessJobError, match=r"wrote its result but exited with code -6") as exc:
        run_in_subprocess(code, str(marker))
    assert exc.value.returncode == -6 and marker.read_text() == "x"
    with pytest.raises(SubprocessJobError, match="timed out"):
        run_in_subprocess("import time; time.sleep(60); result = 0", timeout=2)
