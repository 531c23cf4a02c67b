"""Real-time factor of the full R1 2:1 trip (bottom to top landing, S-curve drive, outputs every
1 ms), single core. Target: >= 200x faster than real time.

    python benchmarks/trip_2to1.py
"""
from pathlib import Path
import sys

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from reeve_fmu.studies.bench import time_trip  # noqa: E402

if __name__ == "__main__":
    root = Path(__file__).resolve().parents[1]
    # 0.5 s start delay + 27.175 s S-curve; outputs every 1 ms
    r = time_trip(root / "scenes" / "elevator_2to1.toml", t_end=27.675, out_dt=1e-3, repeat=5)
    print(f"2:1 trip: {r['t_end_s']} s simulated in {r['wall_s']*1e3:.1f} ms -> "
          f"real-time factor {r['rtf']:.0f}x ({r['us_per_step']:.2f} us/step, "
          f"{r['newton_iter_per_step']:.2f} Newton iterations/step, {r['n_dof']} dof); target >= 200x")
