"""Real-time factor of the slewing jib crane in dynamics (scenes/slewing_crane.toml: slew and hoist,
one linear element per span, exact tangents, a rigid box payload), single core, with the 2:1
elevator trip measured in the same run for comparison. Target: crane >= 50x real time.

    python benchmarks/crane_speed.py [--t-end 20]
"""
from pathlib import Path
import argparse
import os
import sys
import time

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from reeve_fmu.core.model import build_model  # noqa: E402
from reeve_fmu.core.scene import load_scene  # noqa: E402
from reeve_fmu.core.solver import Simulator  # noqa: E402
from reeve_fmu.studies.bench import time_trip  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def crane_rtf(t_end: float, repeat: int = 3) -> dict:
    """Best of `repeat` runs (statics excluded, outputs every 10 ms)."""
    m = build_model(load_scene(ROOT / "scenes" / "slewing_crane.toml"))
    sim = Simulator(m)
    st0 = sim.initial_state()
    sim.run(t_end=0.1, out_dt=0.01, state=st0.copy())          # compile / load the kernels
    best = float("inf")
    for _ in range(repeat):
        st = st0.copy()
        t0 = time.perf_counter()
        sim.run(t_end=t_end, out_dt=0.01, state=st)
        best = min(best, time.perf_counter() - t0)
    return dict(t_end_s=t_end, wall_s=best, rtf=t_end / best, n_dof=m.nq, steps=int(st.info[1]))


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--t-end", type=float, default=20.0)
    a = ap.parse_args()
    load = os.getloadavg()[0]
    r = crane_rtf(a.t_end)
    e = time_trip(ROOT / "scenes" / "elevator_2to1.toml", t_end=27.675, out_dt=1e-3, repeat=3)
    print(f"load average {load:.2f} (2 cores shared)")
    print(f"slewing crane: {r['t_end_s']:g} s in {r['wall_s']:.2f} s -> {r['rtf']:.1f}x real time "
          f"({r['n_dof']} coordinates); target >= 50x")
    print(f"2:1 elevator trip (same run): {e['rtf']:.0f}x real time ({e['us_per_step']:.2f} us/step)")
