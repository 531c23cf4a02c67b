"""The FMU as a file people copy: an interpreter configured, not guessed; precompiled kernels that need
no compilation on a machine that never ran the model; a standalone FMU that runs where no Python is
installed; honest messages when something does not fit.

Each FMU runs in its own process: the C host (tests/support/fmu_host), `python script.py`, or a job of
tests/support/cosim_jobs.py. The machine without Python is a mount namespace (`unshare -m`, root) in which every
Python location of this machine is hidden.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest

from reeve_fmu.fmu.native import libpython_path, loader_supported
from reeve_fmu.fmu.runner import run_in_subprocess
from tests.support import ROOT
from tests.support.fmu_host import chost

pytestmark = pytest.mark.skipif(not loader_supported(), reason="the native loader is built on Linux x86-64 only: elsewhere no C host can load the FMU (the fmpy tests of the same FMUs still run)")

JOBS = str(ROOT / "tests" / "support" / "cosim_jobs.py")
R1_DRIVE = {"pretorque[1]": 522.5, "pretorque[2]": 331.5}
RECORD = ["car.position", "car.velocity", "motor.speed", "traction.tension_in"]
DRIVE_RECORD = ["motor.torque", "brake.command"]
VERSION = f"{sys.version_info.major}.{sys.version_info.minor}"
#: what a desktop-launched tool or a service has: no Python of ours on PATH, an ASCII locale
MINIMAL = {"PATH": "/usr/bin:/bin", "LANG": "C", "LC_ALL": "C"}


@pytest.fixture(scope="module")
def standalone(tmp_path_factory):
    """Plant and drive FMUs built with `reeve-fmu build --standalone`, extracted."""
    dest = tmp_path_factory.mktemp("standalone")
    p = subprocess.run([sys.executable, "-m", "reeve_fmu.cli", "build", "--standalone", "--dest", str(dest / "fmus")],
                       cwd=ROOT, capture_output=True, text=True, encoding="utf-8", errors="replace", timeout=1800)
    assert p.returncode == 0, p.stdout + p.stderr
    fmus = {"plant": str(dest / "fmus" / "ReevingPlant.fmu"), "drive": str(dest / "fmus" / "ElectricDrive.fmu")}
    return {**fmus, **{f"{k}_dir": str(chost.extract(v, dest / k)) for k, v in fmus.items()}}


@pytest.fixture(scope="module")
def crane_plant(tmp_path_factory):
    """CranePlant.fmu as `reeve-fmu build --scene scenes/slewing_crane.toml` writes it."""
    dest = tmp_path_factory.mktemp("crane")
    p = subprocess.run([sys.executable, "-m", "reeve_fmu.cli", "build", "--scene",
                        str(ROOT / "scenes" / "slewing_crane.toml"), "--dest", str(dest)],
                       cwd=ROOT, capture_output=True, text=True, encoding="utf-8", errors="replace", timeout=1800)
    assert p.returncode == 0, p.stdout + p.stderr
    return str(next(dest.glob("*Plant*.fmu")))


def _minimal_env(extra=None) -> dict:
    env = {"HOME": os.environ.get("HOME", "/root"), **MINIMAL}
    env.update(extra or {})
    return env


def _plan(f, steps=2000, **kw):
    return chost.cosim_plan(f["plant"], f["drive"], f["plant_dir"], f["drive_dir"], step=1e-3, steps=steps,
                            drive_values=R1_DRIVE, record=RECORD, drive_record=DRIVE_RECORD,
                            stop_time=steps * 1e-3, **kw)


def _reference(fmus, steps=2000):
    return run_in_subprocess(f"{JOBS}:fmpy_run", fmus["plant"], fmus["drive"], steps * 1e-3, "gauss-seidel",
                             {}, R1_DRIVE, False, timeout=900)


def _assert_equal_to(rows, ref, steps=2000):
    assert len(rows) == steps + 1
    cols = list(zip(*rows))
    for i, name in enumerate(RECORD + DRIVE_RECORD, start=1):
        assert list(cols[i]) == ref[name], name                        # exact float equality
    assert max(ref["brake.command"]) == 1.0 and ref["car.position"][-1] > 0.1   # the car moves


# ------------------------------------------------------------------------------------------------
# 1. the interpreter is configured, not guessed
# ------------------------------------------------------------------------------------------------
def _foreign_python(base: Path) -> Path:
    """A prefix with a `python3` and a standard library that is not the build's: an interpreter that
    guesses its prefix from the first python3 on PATH takes this one and cannot even import `encodings`."""
    (base / "bin").mkdir(parents=True)
    exe = base / "bin" / "python3"
    exe.write_text("#!/bin/sh\necho 'another Python build'\nexit 1\n", encoding="utf-8")
    exe.chmod(0o755)
    lib = base / "lib" / f"python{VERSION}"
    lib.mkdir(parents=True)
    (lib / "os.py").write_text("raise ImportError('the standard library of another Python build')\n",
                               encoding="utf-8")
    return base


def test_c_host_with_another_python_first_on_path(fmus, host, unzipped, tmp_path):
    """The C host with PATH=<another python3>:/usr/bin:/bin, LANG=C, no PYTHON* variables: the loader
    starts the build's libpython with its own home, and 2000 steps equal fmpy's run bit for bit."""
    other = _foreign_python(tmp_path / "other")
    f = {**fmus, "plant_dir": unzipped["plant"], "drive_dir": unzipped["drive"]}
    env = _minimal_env({"PATH": f"{other / 'bin'}:/usr/bin:/bin"})
    r = chost.run_host(host, _plan(f), tmp_path, env=env)
    assert r["returncode"] == 0, r["stdout"] + r["stderr"]
    assert "[ERROR]" not in r["stderr"] and "[FATAL]" not in r["stderr"], r["stderr"]
    _assert_equal_to(r["rows"], _reference(fmus))


def test_the_python_home_can_be_overridden(fmus, host, unzipped, tmp_path):
    """REEVE_FMU_PYTHONHOME wins over what the loader would choose: pointed at a prefix without a
    standard library, the host gets the reason, naming that home, and no crash."""
    other = _foreign_python(tmp_path / "other")
    f = {**fmus, "plant_dir": unzipped["plant"], "drive_dir": unzipped["drive"]}
    r = chost.run_host(host, _plan(f, steps=5), tmp_path, env=_minimal_env({"REEVE_FMU_PYTHONHOME": str(other)}))
    assert r["returncode"] == 1, r
    assert "has no standard library under its home " + str(other) in r["stderr"], r["stderr"]
    assert "REEVE_FMU_PYTHONHOME" in r["stderr"] and "fmi2Instantiate of drive returned NULL" in r["stderr"]


# ------------------------------------------------------------------------------------------------
# 2. precompiled kernels travel with the FMU
# ------------------------------------------------------------------------------------------------
COLD_RUN = """
import json, os, sys, time
t0 = time.perf_counter()
from fmpy import simulate_fmu
res = simulate_fmu(sys.argv[1], stop_time=1.0, step_size=1e-3, output_interval=1e-3)
import reeve_fmu
print(json.dumps({"wall_s": time.perf_counter() - t0, "boot": reeve_fmu._reeve_fmu_boot,
                  "samples": len(res), "t_end": float(res["time"][-1])}))
"""


def _cache_files(d: Path) -> set:
    return {p.relative_to(d).as_posix() for p in d.rglob("*") if p.is_file() and p.suffix in (".nbi", ".nbc")}


@pytest.mark.parametrize("which", ["plant", "drive", "crane"])
def test_kernels_in_the_fmu_need_no_compilation_on_an_empty_cache(fmus, crane_plant, tmp_path, which):
    """fmpy.simulate_fmu of 1 s at 1 ms with an empty kernel cache, as on a machine or account that never
    ran the model: the FMU copies its kernels into the cache and numba compiles nothing (it would write
    new index and data files for each kernel it compiled)."""
    fmu = crane_plant if which == "crane" else fmus[which]
    with zipfile.ZipFile(fmu) as zf:
        manifest = json.loads(zf.read("resources/reeve_fmu_kernels/manifest.json"))
        shipped = {n.split("reeve_fmu_kernels/", 1)[1] for n in zf.namelist()
                   if "reeve_fmu_kernels/pkg/" in n}
    assert manifest["cpu"] == "generic" and manifest["python"] == VERSION and shipped
    script = tmp_path / "cold.py"
    script.write_text(COLD_RUN, encoding="utf-8")
    cache = tmp_path / "cache"
    p = subprocess.run([sys.executable, str(script), fmu], capture_output=True, text=True,
                       encoding="utf-8", errors="replace", timeout=900, cwd=tmp_path,
                       env=chost.clean_env({"REEVE_FMU_CACHE_DIR": str(cache)}))
    assert p.returncode == 0, p.stdout + p.stderr
    out = json.loads(p.stdout.strip().splitlines()[-1])
    assert out["boot"]["warning"] is None
    kernel_dir = cache / "numba" / manifest["source_hash"]
    assert _cache_files(kernel_dir) == shipped          # all copied; nothing compiled, nothing added
    assert out["samples"] == 1001 and out["t_end"] == 1.0   # the whole second ran


def _shipped(fmu) -> tuple[str, set]:
    with zipfile.ZipFile(fmu) as zf:
        manifest = json.loads(zf.read("resources/reeve_fmu_kernels/manifest.json"))
        return manifest["source_hash"], {n.split("reeve_fmu_kernels/", 1)[1] for n in zf.namelist()
                                         if "reeve_fmu_kernels/pkg/" in n}


def test_c_host_on_an_empty_cache_compiles_nothing(fmus, host, unzipped, tmp_path):
    """Both FMUs in one native process with an empty kernel cache: each copies its kernels when it is
    instantiated (the second one finds the package already imported), and numba compiles nothing."""
    (h_plant, plant), (h_drive, drive) = _shipped(fmus["plant"]), _shipped(fmus["drive"])
    assert h_plant == h_drive and plant and drive
    f = {**fmus, "plant_dir": unzipped["plant"], "drive_dir": unzipped["drive"]}
    cache = tmp_path / "cache"
    r = chost.run_host(host, _plan(f, steps=200), tmp_path, env=_minimal_env({"REEVE_FMU_CACHE_DIR": str(cache)}))
    assert r["returncode"] == 0 and "[WARNING]" not in r["stderr"], r["stdout"] + r["stderr"]
    assert _cache_files(cache / "numba" / h_plant) == plant | drive


def _with_manifest(src, dest, **changes):
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dest, "w", zipfile.ZIP_DEFLATED) as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename == "resources/reeve_fmu_kernels/manifest.json":
                data = json.dumps({**json.loads(data), **changes}).encode("utf-8")
            zout.writestr(item, data)
    return dest


def test_kernels_of_another_python_are_not_used_and_say_so(fmus, tmp_path):
    """Kernels precompiled for another Python version are left alone, with the logged reason: the
    model then compiles (here with REEVE_FMU_NO_JIT, which keeps the test short, nothing compiles)."""
    fmu = _with_manifest(fmus["plant"], tmp_path / "ReevingPlant.fmu", python="3.99")
    script = tmp_path / "cold.py"
    script.write_text(COLD_RUN, encoding="utf-8")
    p = subprocess.run([sys.executable, str(script), str(fmu)], capture_output=True, text=True, encoding="utf-8",
                       errors="replace", timeout=900, cwd=tmp_path,
                       env=chost.clean_env({"REEVE_FMU_CACHE_DIR": str(tmp_path / "cache"), "REEVE_FMU_NO_JIT": "1"}))
    assert p.returncode == 0, p.stdout + p.stderr
    boot = json.loads(p.stdout.strip().splitlines()[-1])["boot"]
    assert boot["kernels_copied"] == 0 and not (tmp_path / "cache" / "numba").exists()
    warning = "precompiled for Python 3.99 with numba"
    assert warning in boot["warning"] and f"this is Python {VERSION}" in boot["warning"]
    assert warning in p.stdout + p.stderr                # the loader's preflight logged it to the host


# ------------------------------------------------------------------------------------------------
# 3. a standalone FMU on a machine without Python
# ------------------------------------------------------------------------------------------------
def _python_locations() -> tuple[list, list]:
    """(directories, files) that make up the Pythons of this machine: interpreter prefixes, virtual
    environments, the distribution's stdlib, every libpython and python executable, the user cache."""
    dirs = {sys.base_prefix, sys.prefix, os.path.expanduser("~/.cache/reeve_fmu"), os.path.expanduser("~/.pyenv")}
    dirs |= {str(p) for p in ROOT.glob(".venv*")}
    for base in ("/usr/lib", "/usr/local/lib", "/usr/lib64", "/usr/share"):
        dirs |= {str(p) for p in Path(base).glob("python3*") if p.is_dir()}
    files = set()
    for base in ("/usr/lib", "/usr/lib/x86_64-linux-gnu", "/usr/local/lib", "/lib/x86_64-linux-gnu", "/usr/lib64"):
        files |= {os.path.realpath(p) for p in Path(base).glob("libpython3*") if p.exists()}
    for base in ("/usr/bin", "/usr/local/bin", "/bin"):
        files |= {os.path.realpath(p) for p in Path(base).glob("python*") if p.exists()}
    dirs = {os.path.realpath(d) for d in dirs if os.path.isdir(d)}
    dirs = sorted(d for d in dirs if not any(d.startswith(o + "/") for o in dirs))   # outermost only
    files = sorted(f for f in files if os.path.isfile(f) and not any(f.startswith(d + "/") for d in dirs))
    return dirs, files


def _without_python_argv(cmd: list, readonly=()) -> list:
    """argv running cmd in a mount namespace without any Python of this machine; `readonly`: folders
    made read-only there (an FMU extracted where the host cannot write)."""
    dirs, files = _python_locations()
    mounts = [f"mount -t tmpfs none {d}" for d in dirs] + [f"mount --bind /dev/null {f}" for f in files]
    mounts += [f"mount --bind {d} {d}; mount -o remount,bind,ro {d}" for d in readonly]
    probe = ("for p in python3 python; do if command -v $p >/dev/null 2>&1 && $p -c pass 2>/dev/null; "
             "then echo \"python found: $p\" >&2; exit 97; fi; done; "
             f"if ls /usr/lib/python3*/os.py {sys.base_prefix}/lib/python*/os.py 2>/dev/null | grep -q .; "
             "then echo 'a standard library is visible' >&2; exit 98; fi")
    script = "set -e; " + "; ".join(mounts) + "; " + probe + "; exec " + " ".join(f"'{c}'" for c in cmd)
    return ["unshare", "-m", "sh", "-c", script]


def _namespace_available() -> str:
    if os.geteuid() != 0:
        return "hiding Python in a mount namespace needs root (as in CI)"
    if not shutil.which("unshare"):
        return "unshare (util-linux) is not installed"
    return ""


def test_standalone_fmu_runs_in_a_native_host_on_a_machine_without_python(fmus, standalone, host, tmp_path):
    """The C host in a mount namespace with every Python location hidden (prefixes, venvs, stdlibs,
    libpython*, python* executables, the user cache), a minimal environment, an empty kernel cache and
    the extracted FMUs read-only: 2000 steps of the standalone FMUs equal the normal FMUs' fmpy run, exit 0."""
    why = _namespace_available()
    if why:
        pytest.skip(why)  # allowed only where it is true (tests/conftest.py SKIP_POLICY): CI runs as root
    plan = tmp_path / "plan.txt"
    plan.write_text(_plan({**standalone}), encoding="utf-8")
    out = tmp_path / "out.csv"
    env = _minimal_env({"REEVE_FMU_CACHE_DIR": str(tmp_path / "empty-cache")})
    argv = _without_python_argv([str(host), str(plan), str(out)], readonly=(standalone["plant_dir"],
                                                                           standalone["drive_dir"]))
    p = subprocess.run(argv, capture_output=True, text=True,
                       encoding="utf-8", errors="replace", timeout=900, env=env, cwd=tmp_path)
    assert p.returncode == 0, p.stdout + p.stderr
    assert "[ERROR]" not in p.stderr and "[FATAL]" not in p.stderr and "[WARNING]" not in p.stderr, p.stderr
    rows = [[float(x) for x in line.split(",")] for line in out.read_text(encoding="utf-8").splitlines()]
    _assert_equal_to(rows, _reference(fmus))


def test_standalone_fmu_carries_a_trimmed_runtime(standalone):
    with zipfile.ZipFile(standalone["plant"]) as zf:
        names = zf.namelist()
        manifest = json.loads(zf.read("resources/reeve_runtime/manifest.json"))
    rt = "resources/reeve_runtime/"
    assert f"{rt}lib/libpython{VERSION}.so.1.0" in names
    assert {"numpy", "numba", "llvmlite"} <= {k.lower() for k in manifest["packages"]}
    assert not [n for n in names if n.startswith(rt) and ("/tests/" in n or "/test/" in n or "/tkinter/" in n
                                                          or "/idlelib/" in n or n.endswith(".a"))]
    assert any(n.endswith(".pyc") and "/numba/__pycache__/" in n for n in names)


CHECK_IN_FMPY = """
import sys
from fmpy import simulate_fmu
res = simulate_fmu(sys.argv[1], stop_time=0.01, step_size=1e-3, output_interval=1e-3)
print(float(res["car.position"][-1]))
"""


def test_standalone_fmu_in_fmpy_uses_the_hosts_python(standalone, fmus, tmp_path):
    """In a Python host of the bundle's version the standalone FMU runs like the normal one."""
    script = tmp_path / "run.py"
    script.write_text(CHECK_IN_FMPY, encoding="utf-8")
    z = []
    for fmu in (standalone["plant"], fmus["plant"]):
        p = subprocess.run([sys.executable, str(script), fmu], capture_output=True, text=True, encoding="utf-8",
                           errors="replace", timeout=900, cwd=tmp_path, env=chost.clean_env())
        assert p.returncode == 0, p.stdout + p.stderr
        z.append(float(p.stdout.strip().splitlines()[-1]))
    assert z[0] == z[1]


# ------------------------------------------------------------------------------------------------
# 4. honest degradations, 5. bad input
# ------------------------------------------------------------------------------------------------
def test_missing_package_advice_names_this_machine(fmus, host, unzipped, tmp_path):
    """The build's interpreter and venv do not exist here: the advice names a Python of this machine,
    not the build's paths."""
    broken = tmp_path / "broken"
    shutil.copytree(unzipped["drive"], broken)
    env_json = broken / "resources" / "reeve_env.json"
    env = json.loads(env_json.read_text(encoding="utf-8"))
    env["executable"] = "/nonexistent/build-venv/bin/python"
    env["site_packages"] = ["/nonexistent/build-venv/lib/site-packages"]
    env["requirements"].append({"module": "reeve_missing_pkg_xyz", "requirement": "reeve_missing_pkg_xyz>=1",
                                "optional": False})
    env_json.write_text(json.dumps(env), encoding="utf-8")
    f = {**fmus, "plant_dir": unzipped["plant"], "drive_dir": str(broken)}
    r = chost.run_host(host, _plan(f, steps=3), tmp_path, env=_minimal_env())
    assert r["returncode"] == 1, r
    err = r["stderr"]
    here = os.path.join(sys.base_prefix, "bin", f"python{VERSION}")
    assert f"{here} -m pip install 'reeve_missing_pkg_xyz>=1'" in err, err
    assert "/nonexistent/" not in err and "on another machine" in err, err


def _corrupt_runtime(src_dir: str, dest: Path, how: str) -> Path:
    shutil.copytree(src_dir, dest, symlinks=True)
    rt = dest / "resources" / "reeve_runtime"
    lib = rt / "lib" / f"libpython{VERSION}.so.1.0"
    if how == "truncated":
        data = lib.read_bytes()
        lib.write_bytes(data[:4096])
    elif how == "foreign":
        data = bytearray(lib.read_bytes())
        data[18:20] = (183).to_bytes(2, "little")               # EM_AARCH64
        lib.write_bytes(bytes(data))
    elif how == "no-stdlib":
        shutil.rmtree(rt / "lib" / f"python{VERSION}" / "encodings")
    elif how == "damaged-numpy":
        ext = sorted((rt / "lib" / f"python{VERSION}" / "site-packages" / "numpy").rglob("_multiarray_umath*.so"))[0]
        ext.write_bytes(ext.read_bytes()[:4096])
    return dest


@pytest.mark.parametrize("how, reason", [
    ("truncated", "is truncated (4096 bytes; its headers need"),
    ("foreign", "is built for another architecture (ELF class 2, machine 183)"),
    ("no-stdlib", "the FMU's runtime bundle is incomplete"),
    ("damaged-numpy", "the FMU's runtime bundle is damaged: reeve_runtime/lib/python"),
])
def test_a_broken_runtime_bundle_is_a_logged_reason_not_a_crash(standalone, host, tmp_path, how, reason):
    plant = _corrupt_runtime(standalone["plant_dir"], tmp_path / "plant", how)
    drive = _corrupt_runtime(standalone["drive_dir"], tmp_path / "drive", how)
    plan = _plan({**standalone, "plant_dir": str(plant), "drive_dir": str(drive)}, steps=3)
    r = chost.run_host(host, plan, tmp_path, env=_minimal_env())
    assert r["returncode"] == 1, r                                     # a clean failure, not a signal
    assert reason in r["stderr"] and "fmi2Instantiate of drive returned NULL" in r["stderr"], r["stderr"]


def test_standalone_fmu_with_an_unwritable_cache_runs_and_says_why(standalone, host, tmp_path):
    """No writable cache or home: the kernels cannot be copied there; the model runs from the extracted
    resources and the host is told (REEVE_FMU_NO_JIT keeps the test short)."""
    nowhere = "/proc/reeve-fmu-nowhere"
    env = _minimal_env({"HOME": nowhere, "XDG_CACHE_HOME": nowhere, "REEVE_FMU_CACHE_DIR": nowhere,
                        "TMPDIR": nowhere, "REEVE_FMU_NO_JIT": "1"})
    r = chost.run_host(host, _plan(standalone, steps=5), tmp_path, env=env)
    assert r["returncode"] == 0, r["stdout"] + r["stderr"]
    assert "could not use the package cache" in r["stderr"] and len(r["rows"]) == 6


def test_standalone_fmu_in_a_python_host_of_another_version_says_why(tmp_path):
    """A Python host of another minor version than the bundle's lacks a package: the reason says that
    the bundle cannot serve this Python and what to install into the host's own."""
    from reeve_fmu.fmu import _bootstrap

    res = tmp_path / "resources"
    (res / "reeve_runtime").mkdir(parents=True)
    (res / "reeve_runtime" / "manifest.json").write_text(json.dumps({"python_version": "3.99", "libraries": {}}),
                                                         encoding="utf-8")
    (res / "reeve_env.json").write_text(json.dumps({"python_version": "3.99", "requirements": [
        {"module": "reeve_missing_pkg_xyz", "requirement": "reeve_missing_pkg_xyz>=1", "optional": False}]}),
        encoding="utf-8")
    err, warning = _bootstrap.preflight(str(res), embedded=False)
    assert f"carries its own Python 3.99 runtime, which a Python {VERSION} host cannot use" in err, err
    assert f"{sys.executable} -m pip install 'reeve_missing_pkg_xyz>=1'" in err, err
    assert warning is None
