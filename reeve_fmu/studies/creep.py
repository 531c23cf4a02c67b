"""Rope creep on the rim against the rigid rim: car position minus rim travel over a trip.

For each scene the trip is run with sheave_contact = "creep" (the default) and "rigid"; the drift is
car travel - R x motor angle / roping (what a drive reads from its encoder against where the car is).
With the rigid rim the car runs ahead by ~eps x travel; with creep it follows the rim up to the
change of the span elongations.

    python -m reeve_fmu.studies.creep [--plot docs/img/creep_drift.png] [--json out.json]
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from ..core.model import build_model
from ..core.scene import default_scene, load_scene
from ..core.solver import Simulator

CASES = (("2:1 R1 trip", "elevator_2to1.toml"), ("1:1 high-rise trip", "elevator_1to1_highrise.toml"))


def drift_run(scene_path, mode: str, out_dt: float = 1e-2) -> dict:
    """Run the scene's trip with sheave_contact = mode; returns time, drift [m] (car travel minus
    rim travel / roping), the car travel and the largest traction ratio."""
    scene = load_scene(scene_path).with_overrides(sheave_contact=mode)
    m = build_model(scene)
    sim = Simulator(m)
    res = sim.run(scene.t_end, out_dt)
    dv = scene.drive
    R = next(s.radius for s in scene.sheaves if s.name == dv.sheave)
    car = res["car.position"] - res["car.position"][0]
    rim = R * (res["motor.angle"] - res["motor.angle"][0]) / dv.roping
    ratio = [res[n] for n in res.names if n.endswith(".traction_ratio")]
    return dict(time=res.time, drift=car - rim, travel=float(car[-1]),
                traction_ratio_max=float(np.max(ratio[0])) if ratio else float("nan"))


def study(out_dt: float = 1e-2) -> dict:
    out = {}
    for label, name in CASES:
        runs = {mode: drift_run(default_scene(name), mode, out_dt) for mode in ("rigid", "creep")}
        out[label] = runs
    return out


def summary(out: dict) -> dict:
    return {label: {mode: dict(travel_m=r["travel"], drift_end_m=float(r["drift"][-1]),
                               drift_max_abs_m=float(np.max(np.abs(r["drift"]))),
                               traction_ratio_max=r["traction_ratio_max"])
                    for mode, r in runs.items()} for label, runs in out.items()}


def plot(out: dict, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, len(out), figsize=(5.2 * len(out), 3.6))
    for ax, (label, runs) in zip(np.atleast_1d(axes), out.items()):
        for mode, style in (("rigid", "--"), ("creep", "-")):
            r = runs[mode]
            ax.plot(r["time"], r["drift"] * 1e3, style, label=f"{mode} rim")
        ax.set_title(label)
        ax.set_xlabel("t [s]")
        ax.set_ylabel("car travel - rim travel / roping [mm]")
        ax.grid(True, alpha=0.3)
        ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--plot", default=None)
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    out = study()
    s = summary(out)
    print(json.dumps(s, indent=2))
    if a.json:
        Path(a.json).write_text(json.dumps(s, indent=2), encoding="utf-8")
    if a.plot:
        plot(out, a.plot)


if __name__ == "__main__":
    main()
