"""The FMUs as drop-in components: a native C host without LD_PRELOAD/PYTHONPATH, clean process exit in
fmpy scripts, errors that reach the host's logger, locale independence, and the loader's layout.

Every FMU-loading check runs in its own process: the C host (tests/support/fmu_host/fmu_host.c, compiled here;
skipped with the reason when no C compiler exists), plain `python script.py` runs judged by their exit
code, or jobs of tests/support/cosim_jobs.py via run_in_subprocess.
"""
from __future__ import annotations

import ast
import json
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from reeve_fmu.fmu.runner import run_in_subprocess
from reeve_fmu.fmu.native import loader_supported
from tests.support import ROOT
from tests.support.checks import check
from tests.support.fmu_host import chost

pytestmark = pytest.mark.skipif(not loader_supported(), reason="the native loader is built on Linux x86-64 only: elsewhere no C host can load the FMU (the fmpy tests of the same FMUs still run)")

JOBS = str(ROOT / "tests" / "support" / "cosim_jobs.py")
R1_DRIVE = {"pretorque[1]": 522.5, "pretorque[2]": 331.5}
RECORD = ["car.position", "car.velocity", "car.acceleration", "motor.speed", "traction.tension_in",
          "traction.traction_ratio"]
DRIVE_RECORD = ["motor.torque", "brake.command"]
ASCII_LOCALE = {"LANG": "C", "LC_ALL": "C", "PYTHONUTF8": "0", "PYTHONCOERCECLOCALE": "0"}


@pytest.fixture(scope="module")
def crane_fmus(tmp_path_factory):
    """CranePlant.fmu and CraneDrive.fmu as a user builds them (`reeve-fmu build --scene
    scenes/slewing_crane.toml`), with the drive's start values sized for the scene (CranePlant.drive.json)."""
    dest = tmp_path_factory.mktemp("crane_fmus")
    p = subprocess.run([sys.executable, "-m", "reeve_fmu.cli", "build", "--scene",
                        str(ROOT / "scenes" / "slewing_crane.toml"), "--dest", str(dest)],
                       cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stdout + p.stderr
    return {"plant": str(dest / "CranePlant.fmu"), "drive": str(dest / "CraneDrive.fmu"),
            "drive_values": json.loads((dest / "CranePlant.drive.json").read_text(encoding="utf-8"))["drive"]}


def _run_script(code: str, tmp_path, name: str, env=None, timeout=300) -> subprocess.CompletedProcess:
    script = tmp_path / name
    script.write_text(code, encoding="utf-8")
    return subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                          encoding="utf-8", errors="replace", timeout=timeout, cwd=tmp_path,
                          env=chost.clean_env(env))


# ------------------------------------------------------------------------------------------------
# layout: the loader is in front of pythonfmu's binary; the FMU records its environment
# ------------------------------------------------------------------------------------------------
def _dynamic_symbols(path) -> set:
    p = subprocess.run(["nm", "-D", "--defined-only", str(path)], capture_output=True, text=True,
                       encoding="utf-8", errors="replace", timeout=600)
    assert p.returncode == 0, p.stderr
    return {line.split()[-1] for line in p.stdout.splitlines() if line.strip()}


def test_loader_layout_symbols_and_recorded_environment(fmus, unzipped):
    if shutil.which("nm") is None:
        pytest.skip("nm (binutils) is not installed")
    for key, ident in (("plant", "ReevingPlant"), ("drive", "ElectricDrive")):
        with zipfile.ZipFile(fmus[key]) as zf:
            names = set(zf.namelist())
            env = json.loads(zf.read("resources/reeve_env.json"))
            reqs = zf.read("resources/requirements.txt").decode("utf-8")
        assert {f"binaries/linux64/{ident}{s}.so" for s in ("", "_pythonfmu", "_pyexit")} <= names
        lib = Path(unzipped[key]) / "binaries" / "linux64"
        loader = _dynamic_symbols(lib / f"{ident}.so")
        helper = _dynamic_symbols(lib / f"{ident}_pyexit.so")
        pyfmu = _dynamic_symbols(lib / f"{ident}_pythonfmu.so")
        fmi = {s for s in pyfmu if s.startswith("fmi2")}
        assert len(fmi) == 34 and {s for s in loader if s.startswith("fmi2")} == fmi   # all of FMI 2.0 CS
        assert "finalizePythonInterpreter" in pyfmu                   # the faulty one ...
        assert "finalizePythonInterpreter" not in loader              # ... is replaced by the helper's
        assert {s for s in helper if not s.startswith("_")} == {"finalizePythonInterpreter"}
        assert env["python_version"] == f"{sys.version_info.major}.{sys.version_info.minor}"
        assert env["site_packages"] and env["loader"]["compiler"]
        mods = {r["module"]: r for r in env["requirements"]}
        assert mods["numpy"]["optional"] is False and mods["numba"]["optional"] is True
        if key == "plant":                                            # the plant compiles its TOML scene
            assert mods["tomli"]["python_below"] == "3.11" and "tomli>=2.0; python_version < '3.11'" in reqs
            assert mods["scipy"]["optional"] is False and "scipy>=1.10" in reqs   # sparsity patterns
        else:
            assert "tomli" not in mods and "scipy" not in mods


def test_faulty_exit_destructor_is_bound_to_the_empty_helper(fmus, tmp_path):
    """pythonfmu's library destructor calls finalizePythonInterpreter through the PLT; the dynamic
    linker must bind that call to the helper's empty definition (LD_DEBUG=bindings), and the fmpy
    script must exit normally."""
    code = ("from fmpy import simulate_fmu\n"
            f"r = simulate_fmu({fmus['drive']!r}, stop_time=0.01, output_interval=1e-3)\n"
            "assert len(r) == 11\n")
    p = _run_script(code, tmp_path, "bindings.py",
                    env={"LD_DEBUG": "bindings", "LD_DEBUG_OUTPUT": str(tmp_path / "ld")})
    assert p.returncode == 0, p.stdout + p.stderr
    lines = [line for f in tmp_path.glob("ld.*") for line in f.read_text(encoding="utf-8", errors="replace")
             .splitlines() if "`finalizePythonInterpreter'" in line]
    assert lines, "no binding of finalizePythonInterpreter recorded"
    for line in lines:
        assert "ElectricDrive_pythonfmu.so" in line and "to " in line, line
        assert line.split(" to ")[1].split()[0].endswith("ElectricDrive_pyexit.so"), line


# ------------------------------------------------------------------------------------------------
# a native C host: no LD_PRELOAD, no PYTHONPATH, bit-identical to fmpy, exit 0
# ------------------------------------------------------------------------------------------------
def test_c_host_runs_plant_and_drive_bit_identical_to_fmpy(fmus, host, unzipped, tmp_path):
    steps, h = 2000, 1e-3
    plan = chost.cosim_plan(fmus["plant"], fmus["drive"], unzipped["plant"], unzipped["drive"], step=h,
                            steps=steps, drive_values=R1_DRIVE, record=RECORD, drive_record=DRIVE_RECORD,
                            stop_time=steps * h)
    r = chost.run_host(host, plan, tmp_path)
    assert r["returncode"] == 0, r["stdout"] + r["stderr"]
    assert "[ERROR]" not in r["stderr"] and "[FATAL]" not in r["stderr"], r["stderr"]
    assert len(r["rows"]) == steps + 1
    ref = run_in_subprocess(f"{JOBS}:fmpy_run", fmus["plant"], fmus["drive"], steps * h, "gauss-seidel",
                            {}, R1_DRIVE, False, timeout=600)
    cols = list(zip(*r["rows"]))
    assert max(abs(a - b) for a, b in zip(cols[0], ref["time"])) < 1e-15   # (k * 1e6) / 1e9 vs k * 1e-3
    for i, name in enumerate(RECORD + DRIVE_RECORD, start=1):
        assert list(cols[i]) == ref[name], name                        # exact float equality
    assert max(ref["brake.command"]) == 1.0 and ref["car.position"][-1] > 0.1   # the car moves


CRANE_RECORD = ["payload.position.z", "payload.swing_radial", "jib.angle", "motor.speed", "tip.tension_out"]


def test_c_host_runs_the_crane_plant_and_drive_like_fmpy(crane_fmus, host, tmp_path):
    """CranePlant.fmu and CraneDrive.fmu in the C host (no LD_PRELOAD, no PYTHONPATH), coupled like
    reeve_fmu.fmu.crane.cosimulate_crane (drive first, slew by speed, 5 ms): loads, steps through the
    start of the slew (1 s) and of the hoist (2 s), reads the outputs, exits 0, and gives what fmpy gives
    (to round-off)."""
    steps, h = 600, 5e-3
    dirs = {k: str(chost.extract(crane_fmus[k], tmp_path / k)) for k in ("plant", "drive")}
    plan = chost.cosim_plan(crane_fmus["plant"], crane_fmus["drive"], dirs["plant"], dirs["drive"], step=h,
                            steps=steps, drive_values=crane_fmus["drive_values"], plant_values={"slew.input": 1},
                            record=CRANE_RECORD, stop_time=steps * h,
                            to_drive=(("motor.speed", "motor.speed"),
                                      ("slew.angular_velocity", "jib.angular_velocity")),
                            to_plant=(("motor.torque", "motor.torque"), ("slew.speed", "slew.speed")))
    r = chost.run_host(host, plan, tmp_path)
    assert r["returncode"] == 0, r["stdout"] + r["stderr"]
    assert "[ERROR]" not in r["stderr"] and "[FATAL]" not in r["stderr"], r["stderr"]
    assert len(r["rows"]) == steps + 1
    ref = run_in_subprocess(f"{ROOT / 'tests' / 'support' / 'crane_jobs.py'}:cosim", crane_fmus["plant"], crane_fmus["drive"],
                            crane_fmus["drive_values"], steps * h, CRANE_RECORD, timeout=900)
    cols = list(zip(*r["rows"][1:]))                  # cosimulate_crane records after each step
    assert max(abs(a - b) for a, b in zip(cols[0], ref["time"])) < 1e-15
    # the host's communication points (k * 5e6 ns) / 1e9 and fmpy's k * 0.005 differ by an ulp at some k, and the
    # drive's S-curves are evaluated there: equal to round-off, not bit for bit once the slew has started (1 s).
    # The bounds cover the round-off of Python 3.10-3.13 with their numpy, which differs by orders of magnitude.
    why = "an ulp of the communication points; its growth differs by Python/numpy version (3.10-3.13)"
    for i, (name, tol) in enumerate(zip(CRANE_RECORD, (1e-13, 5e-17, 5e-18, 1.5e-11, 3e-5)), start=1):
        check(f"crane in the C host against fmpy: {name}", [a - b for a, b in zip(cols[i], ref[name])], tol, why)
    assert ref["jib.angle"][-1] > 1e-3 and ref["payload.position.z"][-1] > ref["payload.position.z"][0]


def test_loader_fast_path_gives_the_results_of_pythonfmus_path(fmus):
    """With the loader's fast path (setReal/getReal through tables shared with the slave, doStep
    called directly) a master sees exactly what pythonfmu's path gives: the exchange, every output,
    a rewind, a rejected input (its reason logged), a reset, fmi2LastSuccessfulTime/fmi2Terminated."""
    on = run_in_subprocess(f"{JOBS}:fast_path_run", fmus["plant"], fmus["drive"], 1, timeout=600)
    off = run_in_subprocess(f"{JOBS}:fast_path_run", fmus["plant"], fmus["drive"], 0, timeout=600)
    assert on["linked"] == {"drive": True, "plant": True}, on["linked"]
    assert off["linked"] == {"drive": False, "plant": False}, off["linked"]
    assert on["table_pending"] == [1, True]           # the torque waited in the table, not in Python
    assert on["relinked"] is True                     # fmi2Reset: the new Python slave is linked
    for key in ("rows", "full", "status", "rewound", "rejected_step", "after_rejected",
                "last_successful_time", "terminated", "plant_time", "after_reset"):
        assert on[key] == off[key], key               # exact float equality
    assert all(list(st) == [0, 0] for st in on["status"])
    assert on["rewound"] == on["rows"][len(on["rows"]) // 2:]
    assert on["rejected_step"] == 2 and on["after_rejected"] == 0
    assert any("brake.command = 2.0 is outside [0.0, 1.0]" in m for m in on["rejected_msgs"])
    assert on["last_successful_time"] == on["plant_time"] and on["terminated"] == 1
    assert max(r[2] for r in on["rows"]) > 500.0      # the exchange is live: the pre-torque (522.5 N m) built up


# ------------------------------------------------------------------------------------------------
# Python hosts: plain fmpy scripts end with exit code 0
# ------------------------------------------------------------------------------------------------
SIMULATE = """
import sys
from fmpy import simulate_fmu
r = simulate_fmu({fmu!r}, stop_time=0.01, output_interval=1e-3)
assert len(r) == 11, len(r)
"""
COSIMULATE = """
from reeve_fmu.fmu.cosim import cosimulate
r = cosimulate({plant!r}, {drive!r}, step=1e-3, t_end=0.01, drive_values={values!r})
assert len(r.time) == 11
"""


def test_fmpy_scripts_exit_cleanly(fmus, tmp_path):
    """simulate_fmu of each FMU and a cosimulate script, 10 runs each (two at a time): every run exits 0
    (pythonfmu's own binary aborted such runs at exit with "corrupted double-linked list")."""
    scripts = {"plant": SIMULATE.format(fmu=fmus["plant"]), "drive": SIMULATE.format(fmu=fmus["drive"]),
               "cosim": COSIMULATE.format(plant=fmus["plant"], drive=fmus["drive"], values=R1_DRIVE)}
    assert chost.failed_runs(scripts, tmp_path, chost.clean_env({"PYTHONPATH": str(ROOT)})) == []


CRANE_COSIMULATE = """
from reeve_fmu.fmu.crane import cosimulate_crane
r = cosimulate_crane({plant!r}, {drive!r}, step=5e-3, t_end=0.05, drive_values={values!r})
assert len(r.time) == 10
"""


def test_crane_fmpy_scripts_exit_cleanly(crane_fmus, tmp_path):
    """The crane plant FMU in the same scripts: simulate_fmu of CranePlant.fmu and a cosimulate_crane
    script (plant and drive), 10 runs each: every run exits 0."""
    scripts = {"crane_plant": SIMULATE.format(fmu=crane_fmus["plant"]),
               "crane_cosim": CRANE_COSIMULATE.format(plant=crane_fmus["plant"], drive=crane_fmus["drive"],
                                                      values=crane_fmus["drive_values"])}
    assert chost.failed_runs(scripts, tmp_path, chost.clean_env({"PYTHONPATH": str(ROOT)})) == []


def test_failing_step_reason_reaches_a_default_fmpy_user(fmus, tmp_path):
    """simulate_fmu with default options (debug_logging=False): 1 MN m drives the car into the
    machine; the run ends early and the solver's reason is printed by fmpy's default logger."""
    code = ("import numpy as np\nfrom fmpy import simulate_fmu\n"
            "inp = np.array([(0.0, 1e6, 1.0), (1.0, 1e6, 1.0)], dtype=[('time', 'f8'), ('motor.torque', 'f8'),"
            " ('brake.command', 'f8')])\n"
            f"r = simulate_fmu({fmus['plant']!r}, stop_time=1.0, output_interval=0.3, input=inp)\n"
            "print('END', r['time'][-1])\n")
    p = _run_script(code, tmp_path, "fail.py")
    assert p.returncode == 0, p.stdout + p.stderr
    assert "[ERROR]" in p.stdout and "SolverError" in p.stdout, p.stdout[-3000:]
    assert "minimum material length" in p.stdout or "did not converge" in p.stdout
    assert "END 0.0" in p.stdout                                      # the run stopped at the failure


# ------------------------------------------------------------------------------------------------
# bad input to the loader: a logged reason and NULL, never a crash (loggingOn = 0 in the host)
# ------------------------------------------------------------------------------------------------
def _broken_env_fmu(src, dest, module):
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dest, "w", zipfile.ZIP_DEFLATED) as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename == "resources/reeve_env.json":
                env = json.loads(data)
                env["requirements"].append({"module": module, "requirement": f"{module}>=1", "optional": False})
                data = json.dumps(env).encode("utf-8")
            zout.writestr(item, data)
    return dest


def test_errors_reach_the_host_logger_with_logging_off(fmus, host, unzipped, tmp_path):
    broken = chost.extract(_broken_env_fmu(fmus["drive"], tmp_path / "Broken.fmu", "reeve_missing_pkg_xyz"),
                           tmp_path / "broken")
    plan = chost.cosim_plan(fmus["plant"], fmus["drive"], unzipped["plant"], str(broken), step=1e-3, steps=5)
    r = chost.run_host(host, plan, tmp_path)
    assert r["returncode"] == 1, r                                     # a clean failure, not a signal
    err = r["stderr"]
    assert "[ERROR] drive:" in err and "reeve_missing_pkg_xyz" in err and "-m pip install" in err, err
    assert "fmi2Instantiate of drive returned NULL" in err
    ok_plan = chost.cosim_plan(fmus["plant"], fmus["drive"], unzipped["plant"], unzipped["drive"], step=1e-3,
                               steps=5)
    r = chost.run_host(host, ok_plan, tmp_path,
                       env=chost.clean_env({"REEVE_FMU_LIBPYTHON": str(tmp_path / "libpython3.99.so.1.0")}))
    assert r["returncode"] == 1 and "cannot be loaded" in r["stderr"] and "[FATAL] drive:" in r["stderr"], r
    old = sorted(Path(sys.base_prefix).parent.glob("3.[89].*/lib/libpython3.*.so.1.0"))
    if old:                                                            # e.g. a pyenv 3.8/3.9 next to ours
        r = chost.run_host(host, ok_plan, tmp_path, env=chost.clean_env({"REEVE_FMU_LIBPYTHON": str(old[0])}))
        assert r["returncode"] == 1 and "wrong Python version" in r["stderr"], r


def test_unwritable_cache_and_temp_dirs_still_run(fmus, host, unzipped, tmp_path):
    """No writable cache, home or temp directory: the FMUs run from the extracted resources and say
    so through the logger (REEVE_FMU_NO_JIT keeps the test short: no numba compile)."""
    nowhere = "/proc/reeve-fmu-nowhere"
    env = chost.clean_env({"HOME": nowhere, "XDG_CACHE_HOME": nowhere, "REEVE_FMU_CACHE_DIR": nowhere,
                           "TMPDIR": nowhere, "REEVE_FMU_NO_JIT": "1"})
    plan = chost.cosim_plan(fmus["plant"], fmus["drive"], unzipped["plant"], unzipped["drive"], step=1e-3,
                            steps=5, drive_values=R1_DRIVE, record=["car.position"])
    r = chost.run_host(host, plan, tmp_path, env=env)
    assert r["returncode"] == 0, r["stdout"] + r["stderr"]
    assert "could not use the package cache" in r["stderr"] and len(r["rows"]) == 6


# ------------------------------------------------------------------------------------------------
# locale independence
# ------------------------------------------------------------------------------------------------
def test_loading_and_stepping_under_an_ascii_locale(fmus, host, unzipped, tmp_path):
    code = ("import locale, sys\nfrom fmpy import simulate_fmu\n"
            "assert locale.getpreferredencoding(False).lower() in ('ansi_x3.4-1968', 'ascii', 'us-ascii'), "
            "locale.getpreferredencoding(False)\n"
            f"for f in ({fmus['plant']!r}, {fmus['drive']!r}):\n"
            "    assert len(simulate_fmu(f, stop_time=0.01, output_interval=1e-3)) == 11\n")
    p = _run_script(code, tmp_path, "ascii.py", env=ASCII_LOCALE)
    assert p.returncode == 0, p.stdout + p.stderr
    plan = chost.cosim_plan(fmus["plant"], fmus["drive"], unzipped["plant"], unzipped["drive"], step=1e-3,
                            steps=50, drive_values=R1_DRIVE, record=["car.position"])
    r = chost.run_host(host, plan, tmp_path, env=chost.clean_env(ASCII_LOCALE))
    assert r["returncode"] == 0 and len(r["rows"]) == 51, r["stdout"] + r["stderr"]


def test_text_files_are_opened_with_an_explicit_encoding():
    """Static check: no read_text/write_text/open(text mode) without encoding= in the package, the
    FMU entries, cosim/ and benchmarks/ (the locale's encoding is ASCII under LANG=C)."""
    bad = []
    for top in ("reeve_fmu", "fmus", "cosim", "benchmarks"):
        for p in sorted((ROOT / top).rglob("*.py")):
            tree = ast.parse(p.read_text(encoding="utf-8"))
            for n in ast.walk(tree):
                if not isinstance(n, ast.Call):
                    continue
                f = n.func
                name = f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", None)
                kws = {k.arg for k in n.keywords}
                if "encoding" in kws or None in kws:
                    continue
                if name == "read_text" and isinstance(f, ast.Attribute) and not n.args:
                    bad.append(f"{p.relative_to(ROOT)}:{n.lineno} read_text")
                elif name == "write_text" and isinstance(f, ast.Attribute) and len(n.args) == 1:
                    bad.append(f"{p.relative_to(ROOT)}:{n.lineno} write_text")
                elif name == "open" and isinstance(f, ast.Name) and len(n.args) < 4:
                    mode = n.args[1] if len(n.args) > 1 else next(
                        (k.value for k in n.keywords if k.arg == "mode"), ast.Constant("r"))
                    if isinstance(mode, ast.Constant) and "b" not in mode.value:
                        bad.append(f"{p.relative_to(ROOT)}:{n.lineno} open")
    assert bad == []


# ------------------------------------------------------------------------------------------------
# plant + drive as one FMU: fmpy's container, run by the C host
# ------------------------------------------------------------------------------------------------
def test_fmpy_container_runs_in_the_c_host_like_the_jacobi_master(fmus, host, tmp_path):
    """The container steps drive and plant with the values of t (Jacobi), like cosimulate(scheme=
    "jacobi"). It counts its own communication points, so the drive's S-curve time can differ from
    the master's t_k by an ulp: equal to round-off level (3.9e-14 m, 1.0e-11 rad/s, 8.9e-9 N m over 2 s
    here) instead of bit for bit."""
    from reeve_fmu.fmu.container import make_container

    fmu = make_container(fmus["plant"], fmus["drive"], tmp_path / "ReevingSystem.fmu")
    p = subprocess.run([sys.executable, "-m", "fmpy", "validate", str(fmu)], capture_output=True, text=True,
                       encoding="utf-8", errors="replace", timeout=600)
    assert p.returncode == 0, p.stdout + p.stderr
    ident, guid, v = chost.model_info(fmu)
    d = chost.extract(fmu, tmp_path / "container")
    names = ["car.position", "motor.speed", "motor.torque", "brake.command"]
    steps = 2000
    plan = "\n".join([f"fmu sys {d} {ident} {guid}"]
                     + [f"real sys {v[k][1]} {x!r}" for k, x in R1_DRIVE.items()]
                     + [f"output sys {v[n][1]}" for n in names]
                     + ["step 0.001", f"steps {steps}", "stoptime 2.0"]) + "\n"
    r = chost.run_host(host, plan, tmp_path)
    assert r["returncode"] == 0, r["stdout"] + r["stderr"]
    assert len(r["rows"]) == steps + 1
    ref = run_in_subprocess(f"{JOBS}:fmpy_run", fmus["plant"], fmus["drive"], 2.0, "jacobi", {}, R1_DRIVE, False,
                            timeout=600)
    cols = list(zip(*r["rows"]))
    from tests.support.checks import check
    # the container's communication points differ from the master's t_k by ulps, which the plant's Newton
    # stop (tolerance 1e-4) turns into differences at round-off level that vary by platform
    ulps = "an ulp of the communication points, amplified by the plant's Newton stop: platform-dependent"
    for i, (name, tol) in enumerate(zip(names, (3e-13, 1e-10, 8e-8, 0.0)), start=1):
        check(f"container in the C host against the Jacobi master: {name}",
              [a - b for a, b in zip(cols[i], ref[name])], tol, reason=ulps if tol else None)
    assert max(cols[4]) == 1.0 and cols[1][-1] > 0.1


TOOLBOX_CSV = """rule;from_fmu;from_port;to_fmu;to_port
FMU;ElectricDrive.fmu;;;
FMU;ReevingPlant.fmu;;;
LINK;ElectricDrive.fmu;motor.torque;ReevingPlant.fmu;motor.torque
LINK;ElectricDrive.fmu;brake.command;ReevingPlant.fmu;brake.command
LINK;ReevingPlant.fmu;motor.speed;ElectricDrive.fmu;motor.speed
LINK;ReevingPlant.fmu;motor.angle;ElectricDrive.fmu;motor.angle
OUTPUT;ReevingPlant.fmu;car.position;;car.position
OUTPUT;ElectricDrive.fmu;motor.torque;;motor.torque
OUTPUT;ElectricDrive.fmu;brake.command;;brake.command
START;ElectricDrive.fmu;pretorque[1];522.5;
START;ElectricDrive.fmu;pretorque[2];331.5;
"""


def test_fmu_manipulation_toolbox_container_runs_in_the_c_host(fmus, host, tmp_path):
    """The same system combined by fmu-manipulation-toolbox's `fmucontainer` (optional package): its
    default (parallel) schedule is the Jacobi master's; the C host runs it."""
    pytest.importorskip("fmu_manipulation_toolbox", reason="fmu-manipulation-toolbox is not installed")
    for k in ("plant", "drive"):
        shutil.copy2(fmus[k], tmp_path)
    (tmp_path / "system.csv").write_text(TOOLBOX_CSV, encoding="utf-8")
    code = ("import sys\nfrom fmu_manipulation_toolbox.cli.fmucontainer import fmucontainer\n"
            f"sys.argv = ['fmucontainer', '-container', 'system.csv:0.001', '-fmu-directory', {str(tmp_path)!r}, "
            "'-no-auto-input', '-no-auto-output', '-no-auto-link']\nfmucontainer()\n")
    p = _run_script(code, tmp_path, "make_container.py")
    fmu = tmp_path / "system.fmu"
    assert fmu.is_file(), p.stdout + p.stderr
    ident, guid, v = chost.model_info(fmu)
    d = chost.extract(fmu, tmp_path / "unzipped")
    names = ["car.position", "motor.torque", "brake.command"]
    plan = "\n".join([f"fmu sys {d} {ident} {guid}"] + [f"output sys {v[n][1]}" for n in names]
                     + ["step 0.001", "steps 1000", "stoptime 1.0"]) + "\n"
    r = chost.run_host(host, plan, tmp_path)
    assert r["returncode"] == 0, r["stdout"] + r["stderr"]
    ref = run_in_subprocess(f"{JOBS}:fmpy_run", fmus["plant"], fmus["drive"], 1.0, "jacobi", {}, R1_DRIVE, False,
                            timeout=600)
    cols = list(zip(*r["rows"]))
    # torque: the communication points differ from fmpy's by ulps, which moves the plant's Newton path at its
    # tolerance; the bounds as for the fmpy container above
    why = "an ulp of the communication points, amplified by the plant's Newton stop: platform-dependent"
    for i, (name, tol) in enumerate(zip(names, (3e-13, 8e-8, 0.0)), start=1):
        check(f"toolbox container in the C host against the Jacobi master: {name}",
              [a - b for a, b in zip(cols[i], ref[name])], tol, why)
