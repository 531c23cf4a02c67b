"""Real-time factor of the full R1 2:1 trip (bottom to top landing, S-curve drive, outputs every
1 ms) and of the R2 1:1 high-rise trip, single core, wall time, best of 5. Target: >= 200x real time.

    python benchmarks/trip_2to1.py [--json docs/img/trip_2to1.json]
"""
from pathlib import Path
import argparse
import json
import sys

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from reeve_fmu.studies.bench import time_trip, trip_cases  # noqa: E402

if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", default=None, help="write the records here (read by benchmarks/report.py)")
    a = ap.parse_args()
    root = Path(__file__).resolve().parents[1]
    rows = []
    for label, scene, t_end, kw in trip_cases(root):
        r = dict(time_trip(scene, t_end=t_end, out_dt=1e-3, repeat=5, **kw), label=label)
        rows.append(r)
        print(f"{label}: {r['t_end_s']} s simulated in {r['wall_s']*1e3:.1f} ms -> "
              f"real-time factor {r['rtf']:.0f}x ({r['us_per_step']:.2f} us/step, "
              f"{r['newton_iter_per_step']:.2f} Newton iterations/step, {r['n_dof']} dof); target >= 200x",
              flush=True)
    if a.json:
        Path(a.json).write_text(json.dumps(rows, indent=1) + "\n", encoding="utf-8")
