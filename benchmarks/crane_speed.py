"""Real-time factors of the cranes in dynamics, single core, CPU time (time.process_time, robust
under load), best of `--repeat` runs after a warm-up, statics excluded, outputs every 10 ms:

* `linear`: scenes/slewing_crane.toml (slew and hoist, one linear element per span, exact tangents, a
  rigid box payload); target >= 50x real time;
* `cubic`: the same with cubic elements, two per span (the first sway mode of every span: the jib
  span's 6.43 Hz within 1e-4 of the taut string, tests/core/test_cubic_tangents.py); target >= 5x;
* `8fall`: scenes/crane_8fall_hoist.toml when it exists (the 8-fall dynamic hoist); target >= 1x;
* `tower`, `trolley`, `luffing`, `luffing_slew`: scenes/tower_crane.toml (slew 0.6 rad while the
  trolley, a joint on the jib, travels 10 m and the winch on the slewing jib hoists 5 m),
  tower_crane_trolley.toml (trolley travel 10 m + hoist), luffing_crane.toml (luff 0.15 rad + hoist,
  the winch on the boom), luffing_crane_slewing.toml (slew 0.5 rad + luff 0.15 rad on the slewing
  superstructure + hoist), one linear element per span; target >= 50x. With
  `--cases linear,tower,trolley,luffing,luffing_slew` the slewing crane is the baseline of the same run;
* the 2:1 elevator trip (benchmarks/trip_2to1_compare.py compares it with another checkout).

`--other CHECKOUT` measures the cases in that checkout too, alternately in fresh interpreters (warm
numba caches), and prints this / other ratios of CPU time per simulated second.

    python benchmarks/crane_speed.py [--t-end 20] [--repeat 3] [--other CHECKOUT] [--cubic-elements 2]
                                     [--cases linear,cubic,8fall] [--json docs/img/crane_speed.json]
    python benchmarks/crane_speed.py --cases linear,tower,trolley,luffing,luffing_slew --json docs/img/crane_speed_tower.json
"""
from pathlib import Path
import argparse
import json
import os
import subprocess
import sys

ROOT = Path(__file__).resolve().parents[1]
CODE = r"""
import json, sys, time
sys.path.insert(0, {root!r})
from reeve_fmu.core.model import build_model
from reeve_fmu.core.scene import loads_scene
from reeve_fmu.core.solver import Simulator
text = open({scene!r}).read()
if {cubic!r}:
    text = text.replace('[[ropes]]', '[[ropes]]\nelement = "cubic"\nelements_per_span = {n_cubic}', 1)
try:
    m = build_model(loads_scene(text, {scene!r}))
except Exception as e:
    print(json.dumps(dict(error=str(e).splitlines()[0][:200]))); sys.exit()
sim = Simulator(m)
st0 = sim.initial_state()
sim.run(t_end=0.1, out_dt=0.01, state=st0.copy())              # load / compile the kernels
best = float("inf")
for _ in range({repeat}):
    st = st0.copy()
    t0 = time.process_time()
    sim.run(t_end={t_end}, out_dt=0.01, state=st)
    best = min(best, time.process_time() - t0)
print(json.dumps(dict(cpu_s=best, rtf={t_end} / best, n_dof=m.nq, steps=int(st.info[1]),
                      iters_per_step=st.info[2] / st.info[1], jac_builds=int(st.info[3]))))
"""
CASES = {"linear": ("slewing_crane.toml", False, 50.0), "cubic": ("slewing_crane.toml", True, 5.0),
         "8fall": ("crane_8fall_hoist.toml", False, 1.0), "tower": ("tower_crane.toml", False, 50.0),
         "trolley": ("tower_crane_trolley.toml", False, 50.0), "luffing": ("luffing_crane.toml", False, 50.0),
         "luffing_slew": ("luffing_crane_slewing.toml", False, 50.0)}


def run_case(root: Path, case: str, t_end: float, repeat: int, n_cubic: int = 2) -> dict:
    name, cubic, _ = CASES[case]
    scene = ROOT / "scenes" / name
    if not scene.exists():
        return dict(error=f"no scenes/{name}")
    code = CODE.format(root=str(root), scene=str(scene), cubic=cubic, t_end=t_end, repeat=repeat, n_cubic=n_cubic)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=root)
    lines = out.stdout.strip().splitlines()
    return json.loads(lines[-1]) if lines else dict(error=out.stderr.strip().splitlines()[-1][:200])


def elevator(root: Path) -> dict:
    code = ("import json, sys; sys.path.insert(0, {root!r}); from reeve_fmu.studies.bench import time_trip; "
            "print(json.dumps(time_trip({scene!r}, t_end=27.675, out_dt=1e-3, repeat=3)))")
    out = subprocess.run([sys.executable, "-c", code.format(root=str(root), scene=str(ROOT / "scenes" / "elevator_2to1.toml"))],
                         capture_output=True, text=True, check=True, cwd=root)
    return json.loads(out.stdout.strip().splitlines()[-1])


def _line(case, r, target):
    if "error" in r:
        return f"{case}: not available ({r['error']})"
    return (f"{case}: {r['rtf']:.1f}x real time (CPU {r['cpu_s']:.3f} s, {r['n_dof']} coordinates, "
            f"{r['iters_per_step']:.2f} Newton iterations/step, {r['jac_builds']} Newton-matrix builds); "
            f"target >= {target:g}x")


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--t-end", type=float, default=20.0)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--cases", default="linear,cubic,8fall")
    ap.add_argument("--other", type=Path, default=None)
    ap.add_argument("--cubic-elements", type=int, default=2, help="cubic elements per span (cubic case)")
    ap.add_argument("--json", default=None, help="write the records here (read by benchmarks/report.py)")
    a = ap.parse_args()
    loads = [os.getloadavg()[0]]
    records = {}
    for case in a.cases.split(","):
        r = run_case(ROOT, case, a.t_end, a.repeat, a.cubic_elements)
        records[case] = dict(r, t_end_s=a.t_end, target_rtf=CASES[case][2])
        print(_line(case, r, CASES[case][2]), flush=True)
        if a.other is not None and "error" not in r:
            o = run_case(a.other, case, a.t_end, a.repeat, a.cubic_elements)
            r2 = run_case(ROOT, case, a.t_end, a.repeat, a.cubic_elements)      # interleaved: this, other, this
            if "error" in o:
                print(f"  {a.other}: not available ({o['error']})")
            else:
                best = min(r["cpu_s"], r2["cpu_s"])
                print(f"  {a.other}: {o['rtf']:.1f}x; CPU ratio other / this = {o['cpu_s'] / best:.2f}", flush=True)
        loads.append(os.getloadavg()[0])
    e = elevator(ROOT)
    print(f"2:1 elevator trip (same run): {e['rtf']:.0f}x real time ({e['us_per_step']:.2f} us/step, wall)")
    loads.append(os.getloadavg()[0])
    print(f"load average {min(loads):.2f}-{max(loads):.2f} during the run (2 cores shared)")
    if a.json:
        records["elevator_2to1"] = e
        Path(a.json).write_text(json.dumps(records, indent=1) + "\n", encoding="utf-8")
