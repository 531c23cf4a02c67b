"""Coupling error of a brake stop at 10 ms communication steps: FMI 2.0 against FMI 3.0 with early return
(docs/cosim.md, "Early return at events").

    python benchmarks/brake_stop_coupling.py [--fmus DIR] [--fmus3 DIR] [--step 0.01] [--json out.json]

The system: the R1 plant (rated load) and the drive, one move of 3 m from landing 1 to landing 2, then
the stop: zero-speed hold, the brake apply command, the brake engaging (a 20 ms lag), the torque held
and ramped down. Two drive tunings: R1's (control.Kp = 970 N.m.s/rad, designed for 125 us sampling)
and one for 10 ms coupling (Kp / 3, Ti x 3: the coupled loop is then stable at 10 ms).

The reference is the monolithic run (the same Plant and ElectricDrive in one process, Gauss-Seidel
every 0.1 ms). Each co-simulation (Gauss-Seidel at `--step`; FMI 2.0 FMUs, and FMI 3.0 FMUs with early
return, which end steps at the plant's events and at the drive's brake-command switch) runs in its own
process. Errors over the stop, from the reference's brake apply command t_apply to the end of the
torque ramp + 0.3 s:

* engage instant: |t_half - t_half_ref|, t_half where brake.engaged crosses 1/2 (1 - engaged is an
  exponential: interpolated linearly in its logarithm between the samples);
* stop travel: |(x(t_end) - x(t_apply)) - the reference's|, x = car.position (linear interpolation
  at t_apply): the stop's own error, without the error the car arrived with;
* max |car.position - reference| over the stop (with the error the car arrived with).
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from reeve_fmu.components.drive import make_drive  # noqa: E402
from reeve_fmu.components.plant import holding_torques  # noqa: E402
from reeve_fmu.fmu import cosim  # noqa: E402
from reeve_fmu.fmu.runner import run_in_subprocess  # noqa: E402

#: the move: landing 1 at 0 m to landing 2 at 3 m, once
MOVE = {"landing[1]": 0.0, "landing[2]": 3.0, "trip.moves": 1}
#: drive tunings: R1's, and one for 10 ms coupling (the speed PI's gain / 3, its integral time x 3)
TUNINGS = {"R1": {}, "10 ms": {"control.Kp": 970.0 / 3, "control.Ti": 0.127 * 3}}
RECORD = ["car.position", "brake.engaged"]
SETTLE = 0.3


def drive_values(plant_fmu, tuning: str) -> dict:
    scene, _ = cosim.plant_fmu_model(plant_fmu)
    pre = holding_torques(scene, (MOVE["landing[1]"], MOVE["landing[2]"]), 1000.0)
    return {**MOVE, "pretorque[1]": pre[0], "pretorque[2]": pre[1], **TUNINGS[tuning]}


def stop_window(dv) -> tuple:
    """(t_apply, t_end): the brake apply command of the move and the end of its torque ramp + SETTLE."""
    row = make_drive(dv)._sched[0]
    return float(row[4]), float(row[6]) + SETTLE


def cosim_job(plant_fmu, drive_fmu, step, dv, t_end):
    """One co-simulation (run in its own process): time, recorded columns, early-return event times."""
    r = cosim.cosimulate(plant_fmu, drive_fmu, step=step, t_end=t_end, drive_values=dv, record=RECORD,
                         monitor=False)
    return {"time": r.time.tolist(), **{c: r[c].tolist() for c in RECORD + ["motor.torque"]},
            "events": r.info.get("events", [])}


def half_engaged(t, e, t_apply) -> float:
    """The time brake.engaged crosses 1/2 upwards after t_apply (1 - e is an exponential: log-linear
    between the samples)."""
    t, e = np.asarray(t), np.asarray(e)
    k = int(np.argmax((e >= 0.5) & (t >= t_apply)))
    if k == 0 or e[k] < 0.5 or e[k - 1] >= 0.5:
        return math.nan
    a, b = math.log(1.0 - e[k - 1]), math.log(max(1.0 - e[k], 1e-300))
    return float(t[k - 1] + (t[k] - t[k - 1]) * (math.log(0.5) - a) / (b - a))


def errors(ref, run, t_apply, t_end) -> dict:
    """The stop's errors of `run` against `ref` (module docstring); both {"time", "car.position", ...}."""
    t, x = np.asarray(run["time"]), np.asarray(run["car.position"])
    tr, xr = np.asarray(ref["time"]), np.asarray(ref["car.position"])
    w = (t >= t_apply - 1e-9) & (t <= t_end + 1e-9)
    x_ref = np.interp(t[w], tr, xr)
    travel = (np.interp(t_end, t, x) - np.interp(t_apply, t, x))
    travel_ref = (np.interp(t_end, tr, xr) - np.interp(t_apply, tr, xr))
    return {"engage_instant_error_s": abs(half_engaged(t, run["brake.engaged"], t_apply)
                                          - half_engaged(tr, ref["brake.engaged"], t_apply)),
            "stop_travel_error_m": abs(travel - travel_ref),
            "max_position_error_m": float(np.max(np.abs(x[w] - x_ref))),
            "held_torque_Nm": float(np.interp(t_apply + 0.05, t, run["motor.torque"]))}


def measure(pair2, pair3, step=1e-2, tunings=tuple(TUNINGS)) -> dict:
    """The table: per drive tuning, the reference's stop and the errors of the FMI 2.0 pair and of the
    FMI 3.0 pair with early return (each pair: (plant FMU, drive FMU))."""
    out = {}
    for tuning in tunings:
        dv = drive_values(pair2[0], tuning)
        t_apply, t_end = stop_window(dv)
        ref = cosim.monolithic(step=1e-4, t_end=t_end, record_step=1e-3, drive_values=dv, monitor=False,
                               plant_fmu=pair2[0])
        ref = {"time": ref.time, "car.position": ref["car.position"], "brake.engaged": ref["brake.engaged"],
               "motor.torque": ref["motor.torque"]}
        row = {"t_apply": t_apply, "t_end": t_end,
               "reference_half_engaged_s": half_engaged(ref["time"], ref["brake.engaged"], t_apply),
               "reference_held_torque_Nm": float(np.interp(t_apply + 0.05, ref["time"], ref["motor.torque"]))}
        for label, (plant, drive) in (("FMI 2.0", pair2), ("FMI 3.0 early return", pair3)):
            r = run_in_subprocess(f"{Path(__file__).resolve()}:cosim_job", str(plant), str(drive), step, dv, t_end,
                                  timeout=1800)
            row[label] = {**errors(ref, r, t_apply, t_end), "events": [e for e in r["events"] if e >= t_apply - step]}
        out[tuning] = row
    return out


def _fmus(dest, fmi_version):
    plant, _ = cosim.build_plant_fmu(dest, force=False, fmi_version=fmi_version)
    drive, _ = cosim.build_drive_fmu(dest, force=False, fmi_version=fmi_version)
    return str(plant), str(drive)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fmus", default=str(ROOT / "fmus"), help="FMI 2.0 FMU directory (built if missing/stale)")
    ap.add_argument("--fmus3", default=str(ROOT / "fmus" / "fmi3"), help="FMI 3.0 FMU directory (built if "
                                                                          "missing/stale)")
    ap.add_argument("--step", type=float, default=1e-2, help="communication step [s]")
    ap.add_argument("--json", default=None, help="write the figures to this file")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    res = measure(_fmus(args.fmus, 2), _fmus(args.fmus3, 3), args.step)
    print(f"brake stop, Gauss-Seidel at {args.step * 1e3:g} ms against the monolithic 0.1 ms reference")
    print(f"{'drive tuning':14s} {'FMUs':22s} {'engage instant':>15s} {'stop travel':>12s} {'max |dx|':>10s}"
          f" {'held torque':>12s}")
    for tuning, row in res.items():
        print(f"{tuning:14s} {'reference':22s} {'':>15s} {'':>12s} {'':>10s} {row['reference_held_torque_Nm']:9.1f} Nm")
        for label in ("FMI 2.0", "FMI 3.0 early return"):
            e = row[label]
            print(f"{tuning:14s} {label:22s} {e['engage_instant_error_s'] * 1e3:12.3f} ms "
                  f"{e['stop_travel_error_m'] * 1e3:9.3f} mm {e['max_position_error_m'] * 1e3:7.3f} mm "
                  f"{e['held_torque_Nm']:9.1f} Nm")
    print(f"({time.perf_counter() - t0:.0f} s)")
    if args.json:
        Path(args.json).write_text(json.dumps(res, indent=1) + "\n", encoding="utf-8")
    return res


if __name__ == "__main__":
    main()
