"""`reeve-fmu demo` and `reeve-fmu build`.

Until the FMU co-simulation lands (issue 3), the demo runs the R1 2:1 elevator trip with the
kinematic S-curve drive in the core engine and writes results.csv, results.png and summary.json.
"""
from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np


def cli_demo(args) -> int:
    from .cli import default_scene
    from .model import build_model
    from .results import plot_overview, write_csv
    from .scene import load_scene
    from .solver import Simulator

    scene = load_scene(default_scene("elevator_2to1.toml"))
    model = build_model(scene)
    sim = Simulator(model)
    progress = None
    if not getattr(args, "no_progress", False):
        from tqdm import tqdm
        bar = tqdm(total=round(scene.t_end, 3), unit="s sim", bar_format="{l_bar}{bar}| {n:.1f}/{total:.1f} s")

        def progress(t):
            bar.n = round(t, 3)
            bar.refresh()
    t0 = time.perf_counter()
    res = sim.run(scene.t_end, args.step if args.step else scene.output_step, progress=progress)
    wall = time.perf_counter() - t0
    if progress is not None:
        bar.close()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    cols = res.as_dict()
    t = cols.pop("time")
    write_csv(out / "results.csv", t, cols)
    plot_overview(out / "results.png", t, cols, title="R1 2:1 elevator, full trip up (kinematic S-curve drive)")
    summary = {
        "scene": scene.name,
        "simulated_s": float(t[-1]),
        "wall_s": wall,
        "car_travel_m": float(cols["car.position"][-1] - cols["car.position"][0]),
        "car_speed_max_m_s": float(np.max(cols["car.velocity"])),
        "car_acceleration_max_m_s2": float(np.max(np.abs(cols["car.acceleration"]))),
        "traction_ratio_max": float(np.max(cols["traction.traction_ratio"])),
        "motor_torque_peak_Nm": float(np.max(np.abs(cols["motor.torque"]))),
        "traction_tension_in_max_N": float(np.max(cols["traction.tension_in"])),
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    w = max(len(k) for k in summary)
    for k, v in summary.items():
        print(f"  {k:{w}s}  {v:.6g}" if isinstance(v, float) else f"  {k:{w}s}  {v}")
    print(f"-> {out}/results.csv, results.png, summary.json")
    return 0


def cli_build(args) -> int:
    raise SystemExit("reeve-fmu build: the FMU build is part of issue 3 and not available yet")
