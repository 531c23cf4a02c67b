"""Throughput of `reeve-fmu sweep` on a local Dask cluster: a load-case sweep of the R1 2:1 round trip
(load 0-125 % of the rated load, evenly spaced) on 1 and on 2 worker processes; rows per second and
the ratio, with the load average (docs/performance.md, "Sweeps").

    python benchmarks/sweep_throughput.py [--runs 200] [--workers 1,2] [--json FILE]

Each cluster first runs one warm-up task per worker (numba kernels load from the cache: not counted).
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from reeve_fmu.studies import sweep  # noqa: E402


def study(runs: int) -> dict:
    st = {"file": "<benchmark>", "scene": str(ROOT / "scenes" / "elevator_2to1.toml"), "mode": "list",
          "landings": None, "dwell": 3.0, "step": 1e-3, "series": [], "series_dt": 0.01,
          "keys": ["load_percent"]}
    st["runs"] = [{"load_percent": 125.0 * i / max(runs - 1, 1)} for i in range(runs)]
    return st


def measure(n_workers: int, runs: int) -> dict:
    st = study(runs)
    client = sweep.make_client(workers=n_workers)
    try:
        warm = [client.submit(sweep.run_one, study(1), -1, {"load_percent": 100.0}, pure=False, workers=[w])
                for w in client.scheduler_info()["workers"]]
        client.gather(warm)
        load0 = os.getloadavg()
        t0 = time.perf_counter()
        rows = sweep.run_sweep(st, client, progress=False)
        wall = time.perf_counter() - t0
        load1 = os.getloadavg()
    finally:
        client.cluster.close()
        client.close()
    failed = sum(r["verdict"] == "ERROR" for r in rows)
    return {"workers": n_workers, "runs": runs, "failed": failed, "wall_s": wall, "rows_per_s": runs / wall,
            "loadavg_before": load0, "loadavg_after": load1}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=200)
    ap.add_argument("--workers", default="1,2")
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)
    res = [measure(int(w), args.runs) for w in args.workers.split(",")]
    for r in res:
        print(f"{r['workers']} worker(s): {r['runs']} runs ({r['failed']} failed) in {r['wall_s']:.1f} s = "
              f"{r['rows_per_s']:.3f} rows/s (load average {r['loadavg_before'][0]:.2f} -> "
              f"{r['loadavg_after'][0]:.2f}, {os.cpu_count()} CPUs)")
    if len(res) > 1:
        print(f"speed-up {res[-1]['workers']} vs {res[0]['workers']} worker(s): "
              f"{res[-1]['rows_per_s'] / res[0]['rows_per_s']:.2f}x")
    if args.json:
        Path(args.json).write_text(json.dumps(res, indent=1) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
