"""Throughput of `reeve-fmu sweep` on a local Dask cluster: a load-case sweep of the R1 2:1 round trip
(load 0-125 % of the rated load, evenly spaced) on 1 and on 2 worker processes; rows per second and
the ratio, with the load average and the CPU time the workers got (docs/performance.md, "Sweeps").

    python benchmarks/sweep_throughput.py [--runs 200] [--workers 1,2] [--rounds 1] [--plain] [--json FILE]

Each cluster first runs one warm-up task per worker (numba kernels load from the cache: not counted).
--rounds R repeats the measurement in the order 1,2 | 2,1 | 1,2 ... so that a drift of the machine's
background load falls on both sizes; the speed-up is that of the median rows/s per size. --plain also
runs the same runs on a plain process pool (no Dask) of each size: the ceiling the hardware gives.
The workers' CPU share (CPU seconds / (wall x workers)) tells whether they got whole cores; the CPU time
per run (median over the runs) and the speed-up it allows (workers x CPU per run of 1 worker / CPU per
run of n) are the figures that hold on a loaded machine; the main process (client, scheduler, nannies)
CPU share tells what the Dask machinery costs beside the workers.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
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


def _cpu_seconds() -> float:
    import resource

    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _record(kind, n_workers, runs, failed, wall, cpu, load0, load1, run_cpu, main_cpu) -> dict:
    """`run_cpu`: CPU seconds of each run (its worker process during the run); `main_cpu`: CPU seconds of
    this process (client, scheduler and nannies of a local Dask cluster) during the sweep."""
    return {"kind": kind, "workers": n_workers, "runs": runs, "failed": failed, "wall_s": wall,
            "rows_per_s": runs / wall, "worker_cpu_s": cpu, "cpu_share": cpu / (wall * n_workers),
            "run_cpu_median_s": statistics.median(run_cpu), "run_cpu_mean_s": statistics.fmean(run_cpu),
            "main_cpu_s": main_cpu, "main_cpu_share": main_cpu / wall,
            "loadavg_before": load0, "loadavg_after": load1}


def measure(n_workers: int, runs: int) -> dict:
    st = study(runs)
    client = sweep.make_client(workers=n_workers)
    try:
        warm = [client.submit(sweep.run_one, study(1), -1, {"load_percent": 100.0}, pure=False, workers=[w])
                for w in client.scheduler_info()["workers"]]
        client.gather(warm)
        del warm
        cpu0 = sum(client.run(_cpu_seconds).values())
        load0 = os.getloadavg()
        m0 = time.process_time()
        t0 = time.perf_counter()
        rows = sweep.run_sweep(st, client, progress=False)
        wall = time.perf_counter() - t0
        main_cpu = time.process_time() - m0
        load1 = os.getloadavg()
        cpu = sum(client.run(_cpu_seconds).values()) - cpu0
    finally:
        cluster = client.cluster
        client.close()
        cluster.close()
    failed = sum(r["verdict"] == "ERROR" for r in rows)
    return _record("dask", n_workers, runs, failed, wall, cpu, load0, load1, [r["cpu_s"] for r in rows], main_cpu)


def _plain_init():
    for k, v in sweep.WORKER_ENV.items():
        os.environ[k] = v
    sweep.run_one(study(1), -1, {"load_percent": 100.0})      # warm-up: kernels from the cache


def _plain_run(args):
    st, i, p = args
    r = sweep.run_one(st, i, p)
    return r["verdict"], r["cpu_s"]


def measure_plain(n_workers: int, runs: int) -> dict:
    """The same runs on a plain spawn-process pool (no Dask): the ceiling of the hardware."""
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    st = study(runs)
    base = {k: v for k, v in st.items() if k != "runs"}
    ctx = mp.get_context("spawn")
    with ProcessPoolExecutor(n_workers, mp_context=ctx, initializer=_plain_init) as ex:
        list(ex.map(_hold, range(n_workers)))    # every process started and warm
        load0 = os.getloadavg()
        m0 = time.process_time()
        t0 = time.perf_counter()
        out = list(ex.map(_plain_run, [(base, i, p) for i, p in enumerate(st["runs"])]))
        wall = time.perf_counter() - t0
        main_cpu = time.process_time() - m0
        load1 = os.getloadavg()
    failed = sum(v == "ERROR" for v, _ in out)
    return _record("plain", n_workers, runs, failed, wall, float("nan"), load0, load1, [c for _, c in out],
                   main_cpu)


def _hold(_):
    time.sleep(0.5)               # holds this process so that the next task goes to another one


def _line(r: dict) -> str:
    share = "" if r["cpu_share"] != r["cpu_share"] else \
        f", worker CPU share {r['cpu_share']:.2f}, worker CPU per run {r['worker_cpu_s'] / r['runs']:.3f} s"
    return (f"{r['kind']:5s} {r['workers']} worker(s): {r['runs']} runs ({r['failed']} failed) in "
            f"{r['wall_s']:.1f} s = {r['rows_per_s']:.3f} rows/s (load average {r['loadavg_before'][0]:.2f} -> "
            f"{r['loadavg_after'][0]:.2f}{share}, CPU per run median {r['run_cpu_median_s']:.3f} s, main process "
            f"CPU share {r['main_cpu_share']:.3f}, {os.cpu_count()} CPUs)")


def speedups(res: list, kind: str) -> dict:
    """Median rows/s per worker count of one kind, and the speed-up of the largest over the smallest."""
    by = {}
    for r in res:
        if r["kind"] == kind:
            by.setdefault(r["workers"], []).append(r["rows_per_s"])
    med = {w: statistics.median(v) for w, v in sorted(by.items())}
    cpu = {w: statistics.median(r["run_cpu_median_s"] for r in res if r["kind"] == kind and r["workers"] == w)
           for w in med}
    if len(med) < 2:
        return {"median_rows_per_s": med, "run_cpu_s": cpu}
    lo, hi = min(med), max(med)
    # the speed-up the CPU cost of a run allows when every worker has a whole core: independent of the
    # background load as far as the CPU time of a run is
    return {"median_rows_per_s": med, "run_cpu_s": cpu, "speedup": med[hi] / med[lo],
            "cpu_speedup": hi / lo * cpu[lo] / cpu[hi], "of": [hi, lo]}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=200)
    ap.add_argument("--workers", default="1,2")
    ap.add_argument("--rounds", type=int, default=1, help="repeat, alternating the order of the sizes")
    ap.add_argument("--plain", action="store_true", help="also a plain process pool (no Dask) of each size")
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)
    sizes = [int(w) for w in args.workers.split(",")]
    res = []
    for k in range(args.rounds):
        for w in (sizes if k % 2 == 0 else sizes[::-1]):
            res.append(measure(w, args.runs))
            print(_line(res[-1]), flush=True)
            if args.plain:
                res.append(measure_plain(w, args.runs))
                print(_line(res[-1]), flush=True)
    summary = {kind: speedups(res, kind) for kind in ("dask", "plain") if any(r["kind"] == kind for r in res)}
    for kind, s in summary.items():
        if "speedup" in s:
            print(f"{kind}: speed-up {s['of'][0]} vs {s['of'][1]} worker(s) (median rows/s): {s['speedup']:.2f}x; "
                  f"from the CPU per run (whole cores): {s['cpu_speedup']:.2f}x")
    if args.json:
        Path(args.json).write_text(json.dumps({"runs": res, "summary": summary}, indent=1) + "\n",
                                   encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
