"""First use of an FMU on a machine or account that never ran the model, against the warm second use,
measured in one run (each call in a fresh process):

* fmpy: `simulate_fmu(plant, stop_time=1, step_size=1e-3)` with the user's warm kernel cache and with an
  empty one (`REEVE_FMU_CACHE_DIR` a new folder: the FMU copies its precompiled kernels there); with
  `--without-kernels` also the same FMU stripped of its kernels, cold (what every FMU cost before they
  travelled with it: a full compile);
* the C host (tests/support/fmu_host): 1000 steps of plant + drive, a minimal environment (PATH=/usr/bin:/bin,
  LANG=C), warm and cold; with `--standalone` also the standalone FMUs in a mount namespace where every
  Python of the machine is hidden (root only), cold;
* `--cpu`: the 2:1 trip's cost per step with kernels compiled for a generic x86-64 CPU (the default)
  against host-tuned ones (REEVE_FMU_CPU=host), alternately, each in its own process and cache;
* the FMUs' sizes.

    python benchmarks/fmu_cold_start.py [--repeat 3] [--standalone] [--without-kernels] [--cpu]
                                        [--json docs/img/fmu_cold_start.json]
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

SIMULATE = """
import sys, time
t0 = time.perf_counter()
from fmpy import simulate_fmu
simulate_fmu(sys.argv[1], stop_time=1.0, step_size=1e-3, output_interval=1e-3)
print(time.perf_counter() - t0)
"""
TRIP = ("import json, sys; sys.path.insert(0, {root!r}); from reeve_fmu.studies.bench import time_trip; "
        "r = time_trip({scene!r}, t_end=27.675, out_dt=1e-3, repeat=3); print(json.dumps(r))")


def _env(**extra) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "NUMBA_CPU_NAME", "REEVE_FMU_CPU")}
    env.update(extra)
    return env


def fmpy_wall(fmu, cache=None) -> float:
    """Wall seconds of simulate_fmu in a fresh process (cache: a kernel cache folder, None: the user's)."""
    with tempfile.TemporaryDirectory() as tmp:
        script = Path(tmp) / "run.py"
        script.write_text(SIMULATE, encoding="utf-8")
        env = _env(**({"REEVE_FMU_CACHE_DIR": str(cache)} if cache else {}))
        t0 = time.perf_counter()
        p = subprocess.run([sys.executable, str(script), str(fmu)], capture_output=True, text=True, env=env, cwd=tmp)
        wall = time.perf_counter() - t0
    if p.returncode != 0:
        raise RuntimeError(p.stdout + p.stderr)
    return wall


def host_wall(host, plan_text, workdir, env, argv_wrap=None) -> float:
    plan = Path(workdir) / "plan.txt"
    plan.write_text(plan_text, encoding="utf-8")
    argv = [str(host), str(plan), str(Path(workdir) / "out.csv")]
    t0 = time.perf_counter()
    p = subprocess.run(argv_wrap(argv) if argv_wrap else argv, capture_output=True, text=True, env=env, cwd=workdir)
    wall = time.perf_counter() - t0
    if p.returncode != 0:
        raise RuntimeError(p.stdout + p.stderr)
    return wall


def build(dest: Path, standalone: bool) -> dict:
    args = [sys.executable, "-m", "reeve_fmu.cli", "build", "--dest", str(dest)] + (["--standalone"] if standalone else [])
    subprocess.run(args, cwd=ROOT, check=True, capture_output=True)
    return {"plant": dest / "ReevingPlant.fmu", "drive": dest / "ElectricDrive.fmu"}


def strip_kernels(src: Path, dest: Path) -> Path:
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dest, "w", zipfile.ZIP_DEFLATED) as zout:
        for item in zin.infolist():
            if "/reeve_fmu_kernels/" not in item.filename:
                zout.writestr(item, zin.read(item.filename))
    return dest


def cpu_compare(rounds: int, tmp: Path) -> dict:
    code = TRIP.format(root=str(ROOT), scene=str(ROOT / "scenes" / "elevator_2to1.toml"))
    modes = {"generic": _env(REEVE_FMU_CACHE_DIR=str(tmp / "c_generic")),
             "host": _env(REEVE_FMU_CACHE_DIR=str(tmp / "c_host"), REEVE_FMU_CPU="host")}
    rows = {k: [] for k in modes}
    for _ in range(rounds + 1):                    # the first round compiles
        for k, env in modes.items():
            out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env)
            rows[k].append(json.loads(out.stdout.strip().splitlines()[-1])["us_per_step"])
    best = {k: min(v[1:]) for k, v in rows.items()}
    return {"trip_us_per_step": best, "generic_over_host": best["generic"] / best["host"]}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--standalone", action="store_true")
    ap.add_argument("--without-kernels", action="store_true")
    ap.add_argument("--cpu", action="store_true")
    ap.add_argument("--json", type=Path)
    a = ap.parse_args()
    from tests.support.fmu_host import chost
    import test_fmu_portable as portable

    out = {"load_start": os.getloadavg()[0]}
    with tempfile.TemporaryDirectory(prefix="reeve_cold_") as tmp:
        tmp = Path(tmp)
        fmus = build(tmp / "fmus", False)
        out["size_bytes"] = {k: v.stat().st_size for k, v in fmus.items()}
        fmpy_wall(fmus["plant"])                   # the user's cache warm
        warm = [fmpy_wall(fmus["plant"]) for _ in range(a.repeat)]
        cold = [fmpy_wall(fmus["plant"], tmp / f"cold{i}") for i in range(a.repeat)]
        out["fmpy_1s"] = {"warm_s": min(warm), "cold_s": min(cold), "cold_over_warm": min(cold) / min(warm)}
        if a.without_kernels:
            bare = strip_kernels(fmus["plant"], tmp / "ReevingPlant.fmu")
            out["fmpy_1s"]["cold_without_kernels_s"] = fmpy_wall(bare, tmp / "cold_bare")
        host = chost.compile_host(tmp)
        dirs = {k: str(chost.extract(v, tmp / f"x_{k}")) for k, v in fmus.items()}
        plan = portable._plan({**{k: str(v) for k, v in fmus.items()}, "plant_dir": dirs["plant"],
                               "drive_dir": dirs["drive"]}, steps=1000)
        env = portable._minimal_env()
        host_wall(host, plan, tmp, env)
        warm = [host_wall(host, plan, tmp, env) for _ in range(a.repeat)]
        cold = [host_wall(host, plan, tmp, {**env, "REEVE_FMU_CACHE_DIR": str(tmp / f"hcold{i}")})
                for i in range(a.repeat)]
        out["c_host_1000_steps"] = {"warm_s": min(warm), "cold_s": min(cold), "cold_over_warm": min(cold) / min(warm)}
        if a.standalone:
            sa = build(tmp / "standalone", True)
            out["size_bytes"].update({f"{k}_standalone": v.stat().st_size for k, v in sa.items()})
            sdirs = {k: str(chost.extract(v, tmp / f"s_{k}")) for k, v in sa.items()}
            splan = portable._plan({**{k: str(v) for k, v in sa.items()}, "plant_dir": sdirs["plant"],
                                    "drive_dir": sdirs["drive"]}, steps=1000)
            if os.geteuid() == 0 and shutil.which("unshare"):
                cold = [host_wall(host, splan, tmp, {**env, "REEVE_FMU_CACHE_DIR": str(tmp / f"scold{i}")},
                                  portable._without_python_argv) for i in range(a.repeat)]
                out["c_host_1000_steps"]["standalone_no_python_cold_s"] = min(cold)
                out["c_host_1000_steps"]["standalone_cold_over_warm"] = min(cold) / out["c_host_1000_steps"]["warm_s"]
        if a.cpu:
            out["cpu_target"] = cpu_compare(a.repeat, tmp)
    out["load_end"] = os.getloadavg()[0]
    text = json.dumps(out, indent=1)
    print(text)
    if a.json:
        a.json.write_text(text + "\n", encoding="utf-8")


if __name__ == "__main__":
    main()
