"""The 2:1 elevator trip's real-time factor of two checkouts measured alternately in one run (each in
its own interpreter, numba caches warm): does a change make the 1D path pay?

    python benchmarks/trip_2to1_compare.py OTHER_CHECKOUT [--rounds 3]
"""
from pathlib import Path
import argparse
import json
import os
import subprocess
import sys

HERE = Path(__file__).resolve().parents[1]
CODE = ("import json, sys; sys.path.insert(0, {root!r}); from reeve_fmu.studies.bench import time_trip; "
        "r = time_trip({scene!r}, t_end=27.675, out_dt=1e-3, repeat=3); print(json.dumps(r))")


def rtf(root: Path) -> dict:
    code = CODE.format(root=str(root), scene=str(HERE / "scenes" / "elevator_2to1.toml"))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=root)
    return json.loads(out.stdout.strip().splitlines()[-1])


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("other", type=Path)
    ap.add_argument("--rounds", type=int, default=3)
    a = ap.parse_args()
    rtf(a.other), rtf(HERE)     # warm both caches
    rows = {"this": [], "other": []}
    for _ in range(a.rounds):
        rows["other"].append(rtf(a.other)["us_per_step"])
        rows["this"].append(rtf(HERE)["us_per_step"])
    best = {k: min(v) for k, v in rows.items()}
    print(f"load average {os.getloadavg()[0]:.2f}; us/step (best of {a.rounds} rounds x 3 repeats): "
          f"this {best['this']:.3f}, {a.other} {best['other']:.3f}, ratio {best['this'] / best['other']:.3f}")
