"""Error of the Newton tolerance against the time-step error on the R1 2:1 trip (the whole trip, 1D,
one element per span, outputs every 1 ms): each tolerance against a tight run (1e-12) at the same step,
and the time-step error of h = 1 ms against h = 0.25 ms (both at 1e-12). Max over the trip of car
position, traction-sheave tension and car acceleration; wall time best of 3.

    python benchmarks/newton_tol.py [--json docs/img/newton_tol.json]
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from reeve_fmu.core.model import build_model  # noqa: E402
from reeve_fmu.core.scene import load_scene  # noqa: E402
from reeve_fmu.core.solver import Simulator  # noqa: E402

OUT = ("car.position", "traction.tension_in", "car.acceleration")
T_END = 27.675


def run(model, step, tol):
    sim = Simulator(model, step=step, newton_tol=tol)
    sim.run(0.5, 1e-3)                                   # kernels loaded
    best, res = float("inf"), None
    for _ in range(3):
        t0 = time.perf_counter()
        res = sim.run(T_END, 1e-3, state=sim.initial_state())
        best = min(best, time.perf_counter() - t0)
    return {n: np.asarray(res[n]) for n in OUT}, best


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", default=None, help="write the rows here (read by benchmarks/report.py)")
    a = ap.parse_args(argv)
    model = build_model(load_scene(ROOT / "scenes" / "elevator_2to1.toml"))
    ref, _ = run(model, 1e-3, 1e-12)
    fine, _ = run(model, 2.5e-4, 1e-12)
    rows = [dict(setting="time step: h = 1 ms against 0.25 ms", tol=None, rtf=None,
                 **{n: float(np.max(np.abs(ref[n] - fine[n]))) for n in OUT})]
    for tol in (1e-8, 1e-5, 1e-4, 1e-3):
        y, wall = run(model, 1e-3, tol)
        rows.append(dict(setting=f"Newton tolerance {tol:g} against 1e-12", tol=tol, rtf=T_END / wall,
                         **{n: float(np.max(np.abs(y[n] - ref[n]))) for n in OUT}))
    for r in rows:
        print(r, flush=True)
    if a.json:
        Path(a.json).write_text(json.dumps(rows, indent=1) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
