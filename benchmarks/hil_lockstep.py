"""HIL over CAN: lock-step throughput and real-time step timing. Target: lock-step >= 2000 steps/s
(2x real time at a 1 ms SYNC); report p50/p99 step time of the real-time mode.

    python benchmarks/hil_lockstep.py [--t-end 10] [--repeat 3] [--out bench/hil.json] [--quick]

Every configuration runs `reeve_fmu.hil.runners.run_hil` in a fresh interpreter (the plant FMU is loaded there,
docs/cosim.md, 'pythonfmu and fmpy' item 4), with the demo's scenario (R1 2:1, rated load, the built-in ElectricDrive controller) over the
first --t-end seconds of the trip (pre-torque, brake lift, acceleration, full speed). Lock-step rows give
the wall-clock rate (steps/s over the whole run, bench + controller + bus); real-time rows give the bench's
per-cycle work (SYNC -> TPDOs -> plant step) p50/p99, the SYNC lateness p50/p99/max and deadline misses.
"rt" = SCHED_FIFO priority 50 for bench and controller (default in real time; optional in lock-step).
The machine's load average is printed: other processes on a 2-vCPU VM halve the lock-step rate.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from reeve_fmu.fmu.runner import run_in_subprocess  # noqa: E402

JOB = """
from reeve_fmu.hil.runners import HilConfig, run_hil
s = run_hil(HilConfig(**ARGS[0]), log=None)
keys = ("steps", "wall_s", "steps_per_s", "step_time_p50_us", "step_time_p99_us", "step_time_max_us",
        "sync_jitter_p50_us", "sync_jitter_p99_us", "sync_jitter_max_us", "deadline_misses", "frames_rejected",
        "watchdog_trips", "lockstep_timeouts", "rt_priority", "cycle_time_mean_us")
result = {k: s.get(k) for k in keys}
result["reference_dx"] = (s.get("reference") or {}).get("max_abs_diff_car_position")
"""


def run(cfg: dict) -> dict:
    return run_in_subprocess(JOB, cfg, timeout=1800.0)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--t-end", type=float, default=10.0)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--out", default="bench/hil.json")
    ap.add_argument("--quick", action="store_true", help="lock-step virtual + real-time virtual only, once")
    a = ap.parse_args(argv)
    from reeve_fmu.hil.plants import default_plant_fmu
    from reeve_fmu.hil.buses import ensure_multicast

    fmu = str(default_plant_fmu(log=print))
    mc_ok, mc_why = ensure_multicast()
    base = {"fmu_path": fmu, "t_end": a.t_end, "out": None}
    rows = [
        ("lock-step  virtual        FMU", dict(base, plant="fmu")),
        ("lock-step  virtual        FMU  rt", dict(base, plant="fmu", rt_priority=50)),
        ("lock-step  virtual        in-process", dict(base, plant="in-process")),
        ("lock-step  udp_multicast  FMU", dict(base, plant="fmu", bus="udp_multicast")),
        ("lock-step  udp_multicast  FMU  rt", dict(base, plant="fmu", bus="udp_multicast", rt_priority=50)),
        ("real-time  virtual        FMU  rt", dict(base, plant="fmu", realtime=True, compare=False)),
        ("real-time  udp_multicast  FMU  rt", dict(base, plant="fmu", realtime=True, compare=False,
                                                   bus="udp_multicast")),
    ]
    if a.quick:
        rows = [rows[0], rows[5]]
        a.repeat = 1
    if not mc_ok:
        print(f"udp_multicast rows skipped: {mc_why}")
        rows = [r for r in rows if "udp" not in r[0]]
    load0 = os.getloadavg()
    out = {"t_end_s": a.t_end, "repeat": a.repeat, "loadavg_start": load0, "cpus": os.cpu_count(), "rows": {}}
    print(f"load average {load0[0]:.2f} {load0[1]:.2f} {load0[2]:.2f} on {os.cpu_count()} CPUs; "
          f"{a.t_end:g} s of the demo trip per run, {a.repeat} runs each")
    hdr = (f"{'configuration':36s} {'steps/s':>16s} {'step p50/p99 us':>16s} {'SYNC late p50/p99/max us':>25s} "
           f"{'misses':>6s} {'dx_ref m':>9s}")
    print(hdr)
    for name, cfg in rows:
        rs = [run(cfg) for _ in range(a.repeat)]
        rate = [r["steps_per_s"] for r in rs]
        best = max(rs, key=lambda r: r["steps_per_s"])
        med = {k: statistics.median([r[k] for r in rs]) for k in ("steps_per_s", "step_time_p50_us", "step_time_p99_us")
               if all(r[k] is not None for r in rs)}
        late = ""
        if cfg.get("realtime"):
            late = (f"{statistics.median(r['sync_jitter_p50_us'] for r in rs):.0f}/"
                    f"{statistics.median(r['sync_jitter_p99_us'] for r in rs):.0f}/"
                    f"{max(r['sync_jitter_max_us'] for r in rs):.0f}")
        misses = max(r["deadline_misses"] for r in rs) if cfg.get("realtime") else "-"
        dx = best.get("reference_dx")
        rate_s = f"{med['steps_per_s']:.0f} ({min(rate):.0f}-{max(rate):.0f})" if not cfg.get("realtime") \
            else f"{med['steps_per_s']:.0f}"
        print(f"{name:36s} {rate_s:>16s} {med['step_time_p50_us']:7.0f}/{med['step_time_p99_us']:<8.0f} "
              f"{late:>25s} {misses!s:>6s} {('-' if dx is None else f'{dx:.1e}'):>9s}")
        out["rows"][name.strip()] = {"config": cfg, "runs": rs, "median": med}
    out["loadavg_end"] = os.getloadavg()
    p = Path(a.out)
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(json.dumps(out, indent=1, default=str) + "\n", encoding="utf-8")
    print(f"-> {p}  (target: lock-step >= 2000 steps/s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
