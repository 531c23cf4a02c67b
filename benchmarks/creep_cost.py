"""Cost of rope creep on the rim: sheave_contact = "creep" (the default) against "rigid", in one run.

1. The full 2:1 trip (scenes/elevator_2to1.toml, outputs every 1 ms): wall time, best of N, the two
   modes interleaved.
2. The plant FMU's step: `Plant.step` (what the plant FMU's doStep calls; the pythonfmu/fmpy layer
   around it is the same for both modes) for 1 ms communication steps, external torque drive, brake
   released, torque 5 % above the static holding torque: the car starts moving from rest.

Target: creep / rigid <= 1.3 for both.

    python benchmarks/creep_cost.py [--repeat 5] [--steps 5000]
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from reeve_fmu.core.model import build_model  # noqa: E402
from reeve_fmu.core.plant import Plant  # noqa: E402
from reeve_fmu.core.scene import load_scene  # noqa: E402
from reeve_fmu.core.solver import Simulator  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
MODES = ("rigid", "creep")


def trip_walls(repeat: int) -> dict:
    scene = load_scene(ROOT / "scenes" / "elevator_2to1.toml")
    sims = {mode: Simulator(build_model(scene.with_overrides(sheave_contact=mode))) for mode in MODES}
    for sim in sims.values():
        sim.run(1.0, 1e-3)                      # load the compiled kernels
    best = {mode: float("inf") for mode in MODES}
    for _ in range(repeat):
        for mode, sim in sims.items():
            st = sim.initial_state()
            t0 = time.perf_counter()
            sim.run(27.675, 1e-3, state=st)
            best[mode] = min(best[mode], time.perf_counter() - t0)
    return best


def plant_walls(repeat: int, steps: int) -> dict:
    scene = load_scene(ROOT / "scenes" / "elevator_2to1.toml")
    best = {mode: float("inf") for mode in MODES}
    for _ in range(repeat):
        for mode in MODES:
            p = Plant(scene.with_overrides(sheave_contact=mode))
            p.warm_up()
            tau = 1.05 * p.output("brake.torque")     # 5 % above what the applied brake holds
            t0 = time.perf_counter()
            for _k in range(steps):
                p.step(1e-3, tau, 1.0)
            best[mode] = min(best[mode], time.perf_counter() - t0)
    return best


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--steps", type=int, default=5000)
    a = ap.parse_args(argv)
    load0 = os.getloadavg()[0]
    trip = trip_walls(a.repeat)
    plant = plant_walls(max(1, a.repeat // 2), a.steps)
    load1 = os.getloadavg()[0]
    print(f"load average (1 min) {load0:.2f} -> {load1:.2f} on {os.cpu_count()} cores")
    print(f"2:1 trip (27.675 s, out every 1 ms): rigid {trip['rigid'] * 1e3:.1f} ms, creep "
          f"{trip['creep'] * 1e3:.1f} ms, ratio {trip['creep'] / trip['rigid']:.3f} (target <= 1.3)")
    print(f"plant step (1 ms, {a.steps} steps): rigid {plant['rigid'] / a.steps * 1e6:.2f} us, creep "
          f"{plant['creep'] / a.steps * 1e6:.2f} us, ratio {plant['creep'] / plant['rigid']:.3f} "
          f"(target <= 1.3)")


if __name__ == "__main__":
    main()
