"""Run the SSP description cosim/ReevingSystem (plant + drive FMUs) in libcosim (libcosimpy).

    python cosim/run_libcosim.py [--ssp DIR] [--step 1e-3] [--t-end T] [--out results_libcosim.csv]

libcosim (Open Simulation Platform, C++, FMI Library) is an independent master: it reads the SSP
(components, connections, parameter bindings), instantiates the FMUs, and steps them with its
fixed-step algorithm, i.e. Jacobi coupling: every FMU steps from t to t + h with the inputs of t.
The FMUs are those `reeve-fmu build` wrote into fmus/ (SystemStructure.ssd refers to
../../fmus/*.fmu). libcosimpy is an optional dependency: pip install -e '.[cosim]'.

`run_ssp()` is what tests/fmu/test_cosim.py calls (in a fresh interpreter: the FMUs run Python inside
this process, docs/cosim.md, 'pythonfmu and fmpy' item 4). It imports nothing from reeve_fmu, so the FMUs load the package they
carry, as in any third-party host.
"""
from __future__ import annotations

import argparse
import csv
import math
import os
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
DEFAULT_SSP = HERE / "ReevingSystem"
PLANT_RECORD = ("car.position", "car.velocity", "car.acceleration", "motor.speed", "motor.angle",
                "traction.tension_in", "traction.tension_out", "traction.traction_ratio", "brake.torque")
DRIVE_RECORD = ("motor.torque", "brake.command", "car.position_ref")


def run_ssp(ssp_dir: str | os.PathLike = DEFAULT_SSP, step: float = 1e-3, t_end: float = 61.05,
            plant_record=PLANT_RECORD, drive_record=DRIVE_RECORD, log_level: str = "WARNING") -> dict:
    """Simulate the SSP with libcosim; return {"time": [...], "<instance>.<variable>": [...], "info": {...}}.

    Samples are taken after every communication step with a time-series observer: t = step .. n*step
    (the initial values at t = 0 are not included)."""
    from libcosimpy.CosimEnums import CosimVariableType
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimObserver import CosimObserver

    log_output_level(getattr(CosimLogLevel, log_level))
    step_ns = int(round(step * 1e9))
    n = int(math.floor(t_end / step + 1e-9))
    ssd = Path(ssp_dir)
    if not (ssd / "SystemStructure.ssd").is_file():
        raise FileNotFoundError(f"{ssd}/SystemStructure.ssd not found")
    t0 = time.perf_counter()
    ex = CosimExecution.from_ssp_file(str(ssd), step_size=step_ns)
    idx = {}
    for info in ex.slave_infos():
        idx[info.name.decode()] = info.index
    if set(idx) != {"plant", "drive"}:
        raise RuntimeError(f"expected the instances 'plant' and 'drive' in {ssd}, got {sorted(idx)}")
    variables = {}
    for inst, i in idx.items():
        variables[inst] = {v.name.decode(): v.reference for v in ex.slave_variables(i)}
    obs = CosimObserver.create_time_series(buffer_size=n + 2)
    ex.add_observer(obs)
    wanted = [("plant", v) for v in plant_record] + [("drive", v) for v in drive_record]
    for inst, var in wanted:
        if var not in variables[inst]:
            raise KeyError(f"{inst} has no variable {var!r}")
        obs.start_time_series(idx[inst], variables[inst][var], CosimVariableType.REAL)
    t_setup = time.perf_counter() - t0
    t1 = time.perf_counter()
    ok = ex.simulate_until(target_time=n * step_ns)
    wall = time.perf_counter() - t1
    if not ok:
        from libcosimpy.CosimLogging import get_last_error_message  # pragma: no cover
        raise RuntimeError(f"libcosim simulation failed: {get_last_error_message()}")
    out = {}
    times = None
    for inst, var in wanted:
        # from step 1: libcosimpy 0.0.6 trims as many trailing samples as there are step numbers 0
        # in the answer, so asking from step 0 silently loses the last sample
        tp, steps, vals = obs.time_series_real_samples(idx[inst], variables[inst][var], from_step=1,
                                                       sample_count=n)
        out[f"{inst}.{var}"] = list(vals)
        if times is None:
            times = [t * 1e-9 for t in tp]
            out["step_numbers"] = list(steps)
    out["time"] = times
    out["info"] = {"master": "libcosim", "step_s": step, "steps": n, "setup_s": t_setup, "wall_s": wall,
                   "rtf": n * step / wall if wall > 0 else math.inf}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ssp", default=str(DEFAULT_SSP), help="directory with SystemStructure.ssd")
    ap.add_argument("--step", type=float, default=1e-3, help="communication step [s]")
    ap.add_argument("--t-end", type=float, default=61.05, help="end time [s]")
    ap.add_argument("--out", default="results_libcosim.csv", help="CSV of the recorded signals")
    args = ap.parse_args(argv)
    res = run_ssp(args.ssp, args.step, args.t_end)
    info = res.pop("info")
    res.pop("step_numbers")
    cols = ["time"] + [k for k in res if k != "time"]
    with open(args.out, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(cols)
        for row in zip(*(res[c] for c in cols)):
            w.writerow([repr(x) for x in row])
    print(f"libcosim: {info['steps']} steps of {args.step} s in {info['wall_s']:.2f} s "
          f"({info['rtf']:.1f}x real time) -> {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
