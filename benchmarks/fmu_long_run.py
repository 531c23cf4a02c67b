"""Long run of the plant FMU (docs/hard-cases.md, "Long run"): 10^6 doSteps in one instance through fmpy.

Reports resident memory growth and the step time over the run (first vs last 10 % of the steps).
The brake is released and the motor holds the car with a PD loop on the motor angle around the
static holding torque, plus a small 0.5 Hz torque oscillation, so every step does real work. Runs in a subprocess-free fresh interpreter (this script).

    python benchmarks/fmu_long_run.py [--steps N] [--dt DT]
"""
import argparse
import json
import math
import resource
import shutil
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def rss_mb():
    with open("/proc/self/statm", encoding="utf-8") as fh:
        return int(fh.read().split()[1]) * resource.getpagesize() / 2 ** 20


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--steps", type=int, default=1_000_000)
    ap.add_argument("--dt", type=float, default=1e-3)
    ap.add_argument("--out", default=None, help="write the figures as JSON here")
    args = ap.parse_args()
    from reeve_fmu.fmu.cosim import ensure_fmus
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    plant, _ = ensure_fmus(ROOT / "fmus")   # rebuilds if missing or stale
    md = read_model_description(str(plant))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    d = extract(str(plant))
    f = FMU2Slave(guid=md.guid, unzipDirectory=d, modelIdentifier=md.coSimulation.modelIdentifier,
                  instanceName="long")
    f.instantiate(loggingOn=False)
    f.setupExperiment(startTime=0.0)
    f.enterInitializationMode()
    f.exitInitializationMode()
    hold = f.getReal([vr["brake.torque"]])[0] if "brake.torque" in vr else 0.0
    vin = [vr["motor.torque"], vr["brake.command"]]
    vout = [vr["car.position"], vr["motor.speed"], vr["motor.angle"]]
    n, dt = args.steps, args.dt
    blk = max(1, n // 10)
    times, mems = [], []
    t = 0.0
    t_blk = time.perf_counter()
    rss0 = None
    speed, angle = 0.0, 0.0
    for i in range(n):
        tau = hold * (1.0 + 0.01 * math.sin(2 * math.pi * 0.5 * t)) - 3000.0 * angle - 300.0 * speed
        f.setReal(vin, [tau, 1.0])
        f.doStep(currentCommunicationPoint=t, communicationStepSize=dt)
        _, speed, angle = f.getReal(vout)
        t += dt
        if i == 1000:
            rss0 = rss_mb()
        if (i + 1) % blk == 0:
            now = time.perf_counter()
            times.append((now - t_blk) / blk * 1e6)
            mems.append(rss_mb())
            t_blk = now
    z = f.getReal(vout)
    f.terminate()
    f.freeInstance()
    shutil.rmtree(d, ignore_errors=True)
    res = {"steps": n, "dt_s": dt, "rss_after_1000_steps_MB": rss0, "rss_end_MB": mems[-1],
           "rss_growth_MB": mems[-1] - rss0, "us_per_step_first_10pct": times[0],
           "us_per_step_last_10pct": times[-1], "us_per_step_blocks": times, "rss_blocks_MB": mems,
           "car_position_end_m": z[0]}
    print(json.dumps(res, indent=2))
    if args.out:
        Path(args.out).write_text(json.dumps(res, indent=2), encoding="utf-8")
    import os
    os._exit(0)   # skip interpreter finalisation (pythonfmu exit-time heap corruption, docs/cosim.md, 'pythonfmu and fmpy' item 4)


if __name__ == "__main__":
    main()
