"""Verdicts and the one-page report of a `reeve-fmu hil` run.

The record is checked like a demo trip (studies.verdicts) with the drive parameters and the load the
bench actually ran; the co-simulation coupling check is the coupling monitor of the masters
(fmu.cosim.CouplingMonitor) applied to the torque and speed exchanged over the bus; the bench adds its
own checks (drive faults, rejected frames, lock-step timeouts, real-time deadlines). DIR/report.md
carries the verdicts, what each WARN/FAIL means, the key figures and the trip plots (studies.report).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

SOURCE = "HIL bench (docs/hil.md)"


def run_sequence(drive_values) -> tuple:
    """Landing positions (m) the drive visits, starting at its start landing."""
    from ..components.drive import drive_params

    p = drive_params(drive_values)
    return tuple([p.landings[p.start_landing]] + [p.landings[m] for m in p.moves])


def hil_case(cfg, plant):
    """The trip as the bench ran it: the plant's scene (the FMU's own, or the default scene in process),
    the load of cfg.plant_values, the landings the drive visits, and the drive parameters the controller
    ran (the drive FMU's defaults updated with cfg.drive_values)."""
    from ..components.drive import drive_defaults
    from ..fmu import cosim
    from ..studies.trip import trip_case

    path = getattr(plant, "path", None)
    scene = cosim.plant_fmu_model(path)[0] if path is not None else cosim.default_scene_path()
    load = (cfg.plant_values or {}).get("car.load")
    case = trip_case(scene, load=None if load is None else float(load), sequence=run_sequence(cfg.drive_values))
    dv = drive_defaults()
    dv.update(cfg.drive_values or {})
    case.drive_values = dv
    return case


def coupling_report(time_, cols: dict, dt: float, torque_scale: float) -> dict:
    """The coupling monitor over the record. The bench couples like the Jacobi masters: the torque held
    over [t_k, t_k+1) (hil.torque[k]) was computed from the sample before; the drive's new output at
    step k is hil.torque[k+1], computed from the speed sampled at t_k."""
    from ..fmu.cosim import CouplingMonitor

    mon = CouplingMonitor(dt, torque_scale)
    tau = np.asarray(cols["hil.torque"], float).tolist()
    br = np.asarray(cols["hil.brake_command"], float).tolist()
    w = np.asarray(cols["motor.speed"], float).tolist()
    th = np.asarray(cols["motor.angle"], float).tolist()
    t = np.asarray(time_, float).tolist()
    for k in range(len(tau) - 1):
        mon.update(t[k + 1], tau[k], tau[k + 1], br[k], w[k], th[k], th[k + 1])
    return mon.report("hil: Jacobi, one SYNC period transport delay")


def bench_verdicts(summary: dict, injected: bool) -> list:
    """The bench's own checks. With injected faults, faults and rejected frames are the test's stimulus:
    reported as INFO."""
    from ..studies.verdicts import FAIL, INFO, PASS, WARN, Verdict

    out = []
    fault = summary.get("fault")
    note = "" if fault is None else f"{fault['reason']} at t = {fault['at']:.3f} s"
    st = PASS if fault is None else (INFO if injected else FAIL)
    out.append(Verdict("HIL drive fault (watchdog, heartbeat, SYNC, plant)", st, 0.0 if fault is None else 1.0,
                       0.0, "faults", SOURCE + ": a fault stops the car with the brake",
                       note + ("; faults were injected" if injected and fault else "")))
    rej = summary.get("frames_rejected") or 0
    st = PASS if rej == 0 else (INFO if injected else WARN)
    out.append(Verdict("HIL frames rejected", st, float(rej), 0.0, "frames",
                       SOURCE + ": malformed, out-of-range or stale commands", "faults were injected" if injected else ""))
    if summary.get("mode") == "real-time":
        miss = summary.get("deadline_misses") or 0
        out.append(Verdict("HIL real-time deadlines missed", PASS if miss == 0 else WARN, float(miss), 0.0,
                           "cycles", SOURCE + ": each SYNC period's work must fit into the period",
                           f"of {summary.get('steps')} cycles"))
    else:
        to = summary.get("lockstep_timeouts") or 0
        out.append(Verdict("HIL lock-step timeouts", PASS if to == 0 else WARN, float(to), 0.0, "cycles",
                           SOURCE + ": the controller answers every SYNC in lock-step"))
    return out


def add_verdicts(summary: dict, cfg, plant, faults_injected: bool, time_, cols: dict) -> None:
    """summary: trip_metrics, coupling, verdicts, verdict, findings (and verdicts_note when no trip check
    could be made: the reason)."""
    from ..studies.analysis import traction_limits
    from ..studies.trip import summarize
    from ..studies.verdicts import explain, record_verdicts, trip_verdicts, worst

    vs = []
    try:
        case = hil_case(cfg, plant)
    except Exception as exc:  # noqa: BLE001 - e.g. a plant FMU without [elevator]: no trip checks
        case = None
        summary["verdicts_note"] = f"no trip checks: {type(exc).__name__}: {exc}"
    if case is not None:
        info = coupling_report(time_, cols, cfg.dt, float(case.drive_values["torque.max"]))
        summary["coupling"] = info
        limits = traction_limits(case.scene)
        try:
            s = summarize(time_, cols, limits, landings=case.landings)
            summary["trip_metrics"] = s
            vs = trip_verdicts(case, time_, cols, s, limits, info)
        except Exception as exc:  # noqa: BLE001 - a record without a complete trip: the other checks
            summary["trip_metrics"] = {"unavailable": f"{type(exc).__name__}: {exc}"}
            vs = record_verdicts(case, time_, cols, info)
    vs = [v.as_dict() for v in vs + bench_verdicts(summary, faults_injected)]
    metrics = summary.get("trip_metrics") if isinstance(summary.get("trip_metrics"), dict) else None
    summary["verdict"], summary["verdicts"] = worst(vs), vs
    summary["findings"] = explain(vs, metrics)


def _key_figures(summary: dict) -> list:
    rows = []
    for key, label, unit in (("steps_per_s", "steps per second", "1/s"), ("real_time_factor", "real-time factor", ""),
                             ("step_time_p50_us", "bench step time p50", "µs"),
                             ("step_time_p99_us", "bench step time p99", "µs"),
                             ("sync_jitter_p99_us", "SYNC lateness p99", "µs"),
                             ("car_position_final_m", "final car position", "m"),
                             ("car_speed_max_m_s", "max car speed", "m/s"),
                             ("motor_torque_peak_Nm", "peak motor torque", "N·m"),
                             ("traction_tension_in_max_N", "max traction-sheave tension (in)", "N"),
                             ("brake_engaged_at", "brake engaged at", "s"), ("stop_distance_m", "stop distance", "m")):
        v = summary.get(key)
        if v is not None:
            rows.append((label, f"{v:.4g}" if isinstance(v, float) else str(v), unit))
    m = summary.get("trip_metrics") or {}
    if "trip_time_s" in m:
        rows.append(("trip time", " / ".join(f"{x:.2f}" for x in m["trip_time_s"]), "s"))
        rows.append(("max traction ratio", f"{m['traction_ratio_max']:.3f}", ""))
        rows += [(f"stopping error at {k}", f"{e:+.2f}", "mm") for k, e in m["stopping_error_mm"].items()]
    for key, what in (("reference", "the in-process run of the same coupling"),
                      ("vs_demo_scheme", "the in-process run of the demo's coupling")):
        if key in summary:
            rows.append((f"car position: largest difference from {what}",
                         f"{summary[key]['max_abs_diff_car_position']:.3g}", "m"))
    return rows


def write_report(out: Path, cfg, summary: dict, time_, cols: dict) -> Path:
    """DIR/report.md with the trip plots (results.png, traction.png, motor.png, levelling.png)."""
    from ..studies import report
    from ..studies.analysis import traction_limits
    from ..core.scene import load_scene
    from ..fmu.cosim import default_scene_path, plant_fmu_model

    plant = summary.get("plant") or {}
    scene = plant_fmu_model(plant["fmu"])[0] if plant.get("fmu") else load_scene(default_scene_path())
    m = summary.get("trip_metrics") or {}
    stops = [(r["t_stop_s"], r["landing_m"]) for r in m.get("trips", [])]
    dv = cfg.drive_values or {}
    seq = run_sequence(dv)
    title = (f"HIL run: {scene.name}, {(cfg.plant_values or {}).get('car.load', '—')} kg, "
             + " -> ".join(f"{x:g}" for x in seq) + " m")
    pngs = []
    if cols and all(n in cols for n in ("car.position", "car.velocity", "car.acceleration", "motor.speed")):
        pngs = report.plot_trip(out, time_, cols, limits=traction_limits(scene),
                                title=f"{title} ({summary['mode']}, {summary['bus']})", stops=stops)
    scenario = {"bus": summary["bus"], "controller": summary["controller"], "mode": summary["mode"],
                "plant": ", ".join(f"{k} {v}" for k, v in plant.items()), "SYNC period [s]": cfg.dt,
                "cycles": summary["steps"], "simulated [s]": summary["simulated_s"],
                "car load [kg]": (cfg.plant_values or {}).get("car.load"), "landings visited [m]": list(seq),
                "faults injected": ", ".join(cfg.inject) if cfg.inject else "none",
                "plant parameters": dict(cfg.plant_values or {}), "drive parameters": dict(dv)}
    note = summary.get("verdicts_note")
    findings = list(summary.get("findings") or []) + ([note] if note else [])
    return report.write_report(out, title, scenario, _key_figures(summary), summary.get("verdicts") or [], pngs,
                               command="reeve-fmu hil", findings=findings)
