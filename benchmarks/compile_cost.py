"""What a cold kernel cache costs: compile CPU seconds per kernel family, the cold `reeve-fmu demo`
against the warm one, and optionally the cold test suite, for this checkout and another one in one run.

    python benchmarks/compile_cost.py [--baseline OTHER_CHECKOUT] [--suite] [--json docs/img/compile_cost.json]

Every measurement is its own process with an empty kernel cache (REEVE_FMU_CACHE_DIR) and, for the
demo, an empty FMU directory (REEVE_FMU_FMUS), so it compiles everything it uses:

  family   one short run of a scene, the drive or the Lagrangian baseline (the kernels that kind of
           model compiles): CPU seconds of the process, and the seconds numba spent compiling
  demo     `python -m reeve_fmu.cli demo --no-progress` cold (FMU builds and their warm-up runs
           included), then warm in the same cache: wall and CPU seconds and their ratio
  suite    the README's test command cold (benchmarks/ci_cold.py; 5-25 min)

The checkouts run alternately per measurement, so load drifts hit both; read the load average printed
with each row. A family a checkout cannot run (an older API) is reported as missing.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# what each family runs (cwd = the checkout); the listener sums numba's top-level compile time
_LISTEN = """
import json, sys, time
sys.path.insert(0, '.')
from numba.core import event as ev
depth = [0]; spent = [0.0]; t0 = [0.0]
class L(ev.Listener):
    def on_start(self, e):
        if depth[0] == 0:
            t0[0] = time.perf_counter()
        depth[0] += 1
    def on_end(self, e):
        depth[0] -= 1
        if depth[0] == 0:
            spent[0] += time.perf_counter() - t0[0]
ev.register("numba:compile", L())
"""
_SCENE_RUN = """
from reeve_fmu.core.scene import load_scene
from reeve_fmu.core.model import build_model
from reeve_fmu.core.solver import Simulator
Simulator(build_model(load_scene({scene!r}))).run({t_end!r}, 1e-3)
"""
FAMILIES = {
    "elevator, 1D (2:1 R1: statics, steps, outputs)": _SCENE_RUN.format(scene="scenes/elevator_2to1.toml",
                                                                          t_end=0.01),
    "crane, planar, exact tangents (8-fall)": _SCENE_RUN.format(scene="scenes/crane_8fall.toml", t_end=0.01),
    "slewing crane, spatial, joints": _SCENE_RUN.format(scene="scenes/slewing_crane.toml", t_end=0.01),
    "electric drive": """
try:
    from reeve_fmu.components.drive import ElectricDrive
except ImportError:   # a checkout from before components/
    from reeve_fmu.core.drive import ElectricDrive
d = ElectricDrive()
d.step(0.0, 1e-3, 0.0, 0.0)
""",
    "Lagrangian baseline (hanging rope)": """
from reeve_fmu.core.scene import load_scene
from reeve_fmu.studies import lagrangian as lag
sc = load_scene('scenes/hanging_rope.toml')
lag.LagrangianSimulator(lag.build_lagrangian(sc, element_length=2.5, coarse_length=2.5)).run(0.01)
""",
}


def _children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _run(argv, cwd, env) -> tuple[subprocess.CompletedProcess, float, float]:
    cpu0, t0 = _children_cpu(), time.perf_counter()
    p = subprocess.run(argv, cwd=cwd, env=env, capture_output=True, text=True)
    return p, time.perf_counter() - t0, _children_cpu() - cpu0


def family(checkout: Path, name: str, python: str) -> dict:
    code = _LISTEN + FAMILIES[name] + "\nprint(json.dumps({'compile_s': spent[0]}))\n"
    with tempfile.TemporaryDirectory(prefix="reeve_compile_cost_") as tmp:
        env = dict(os.environ, REEVE_FMU_CACHE_DIR=tmp)
        p, wall, cpu = _run([python, "-c", code], checkout, env)
        compiled = sum(1 for _ in Path(tmp).rglob("*.nbc"))
    row = {"family": name, "checkout": str(checkout), "load": round(os.getloadavg()[0], 2)}
    if p.returncode != 0:
        return dict(row, error=(p.stderr.strip().splitlines() or ["?"])[-1][:200])
    inner = json.loads(p.stdout.strip().splitlines()[-1])
    return dict(row, cpu_s=round(cpu, 1), wall_s=round(wall, 1), compile_s=round(inner["compile_s"], 1),
                specializations=compiled)


def demo(checkout: Path, python: str) -> dict:
    argv = [python, "-m", "reeve_fmu.cli", "demo", "--no-progress"]
    with tempfile.TemporaryDirectory(prefix="reeve_demo_cost_") as tmp:
        env = dict(os.environ, REEVE_FMU_CACHE_DIR=str(Path(tmp) / "cache"), REEVE_FMU_FMUS=str(Path(tmp) / "fmus"))
        argv_out = argv + ["--out", str(Path(tmp) / "results")]
        load = os.getloadavg()[0]
        cold, cold_wall, cold_cpu = _run(argv_out, checkout, env)
        warm, warm_wall, warm_cpu = _run(argv_out, checkout, env)
    row = {"checkout": str(checkout), "load": round(load, 2)}
    if cold.returncode != 0 or warm.returncode != 0:
        return dict(row, error=((cold.stderr or warm.stderr).strip().splitlines() or ["?"])[-1][:200])
    return dict(row, cold_wall_s=round(cold_wall, 1), cold_cpu_s=round(cold_cpu, 1), warm_wall_s=round(warm_wall, 1),
                warm_cpu_s=round(warm_cpu, 1), cold_over_warm=round(cold_wall / warm_wall, 2))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baseline", type=Path, help="another checkout, measured alternately with this one")
    ap.add_argument("--python", default=sys.executable, help="interpreter for both checkouts")
    ap.add_argument("--suite", action="store_true", help="also the cold test suite (benchmarks/ci_cold.py)")
    ap.add_argument("--no-demo", action="store_true", help="skip the cold/warm demo")
    ap.add_argument("--json", type=Path, help="write the results here")
    a = ap.parse_args(argv)
    checkouts = [ROOT] + ([a.baseline.resolve()] if a.baseline else [])
    out = {"families": [], "demo": [], "suite": []}
    for name in FAMILIES:
        for c in checkouts:
            out["families"].append(family(c, name, a.python))
            print(json.dumps(out["families"][-1]), flush=True)
    if not a.no_demo:
        for c in checkouts:
            out["demo"].append(demo(c, a.python))
            print(json.dumps(out["demo"][-1]), flush=True)
    if a.suite:
        sys.path.insert(0, str(ROOT / "benchmarks"))
        from ci_cold import README_CMD, run_cold
        for c in checkouts:
            out["suite"].append(run_cold(c, README_CMD, a.python))
            print(json.dumps(out["suite"][-1]), flush=True)
    if a.json is not None:
        names = {str(ROOT): "this checkout"}
        if a.baseline:
            names[str(a.baseline.resolve())] = "baseline"
        for rows in out.values():
            for r in rows:
                r["checkout"] = names.get(r["checkout"], r["checkout"])
        a.json.write_text(json.dumps(out, indent=1) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
