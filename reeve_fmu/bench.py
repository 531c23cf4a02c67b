"""Benchmarks: real-time factor of the elevator trips (issue 2 target: 2:1 trip >= 200x real time).

Speed is measured here, never asserted in tests. Each case is timed after a warm-up run (JIT loaded),
best of `repeat`, single process (one core).
"""
from __future__ import annotations

import json
import os
import time
from pathlib import Path

from .model import build_model
from .scene import load_scene
from .solver import Simulator


def time_trip(scene_path, t_end=None, out_dt=1e-3, repeat=3, **solver_kw):
    scene = load_scene(scene_path)
    model = build_model(scene)
    sim = Simulator(model, **solver_kw)
    t_end = scene.t_end if t_end is None else t_end
    sim.run(min(t_end, 1.0), out_dt)            # warm-up: JIT load/compile
    best = float("inf")
    res = None
    for _ in range(repeat):
        st = sim.initial_state()
        t0 = time.perf_counter()
        res = sim.run(t_end, out_dt, state=st)
        best = min(best, time.perf_counter() - t0)
    info = sim.final_state.info
    return dict(case=scene.name, method=sim.method, step_s=sim.h, rho_inf=sim.rho_inf, t_end_s=t_end,
                out_dt_s=out_dt, n_dof=model.nq, n_samples=len(res.time), wall_s=best, rtf=t_end / best,
                us_per_step=best / info[1] * 1e6, newton_iter_per_step=info[2] / info[1],
                jacobian_builds=int(info[3]), car_end_m=float(res["car.position"][-1]))


def trip_cases(root: Path):
    return [
        ("2:1 R1 trip, 1D, 1 element/span", root / "scenes" / "elevator_2to1.toml", 27.675, {}),
        ("1:1 R2 high-rise trip, 1D", root / "scenes" / "elevator_1to1_highrise.toml", 40.0, {}),
    ]


def cli_bench(args) -> int:
    root = Path(__file__).resolve().parent.parent
    if not (root / "scenes").exists():
        root = Path.cwd()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    records = []
    for label, path, t_end, kw in trip_cases(root):
        r = time_trip(path, t_end=t_end, **kw)
        r["label"] = label
        records.append(r)
        print(f"{label:38s} {r['wall_s']*1e3:8.1f} ms for {t_end:.1f} s  RTF {r['rtf']:7.1f}x  "
              f"{r['us_per_step']:.2f} us/step, {r['newton_iter_per_step']:.2f} Newton it/step")
    (out / "bench.json").write_text(json.dumps(records, indent=2))
    print(f"-> {out / 'bench.json'} (cpu: {os.cpu_count()} cores; single-threaded run)")
    return 0
