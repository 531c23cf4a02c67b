"""The review of a `reeve-fmu hil` run: its summary, verdicts, written results and one-page report.

The record is checked like a demo trip (studies.verdicts) with the drive parameters and the load the
bench actually ran; the co-simulation coupling check is the coupling monitor of the masters
(fmu.cosim.CouplingMonitor) applied to the torque and speed exchanged over the bus; the bench adds its
own checks (drive faults, rejected frames, lock-step timeouts, real-time deadlines). DIR/report.md
carries the verdicts, what each WARN/FAIL means, the key figures and the trip plots (studies.report).
"""
from __future__ import annotations

import json
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


def _pct(a, q):
    return float(np.percentile(a, q)) if len(a) else None


def summarize(cfg, faults, res, plant, cols: dict, ctl_stats) -> dict:
    """The run's summary: mode and timing, fault handling, frame counts, step-time percentiles."""
    from .protocol import ERR_HEARTBEAT, ERR_PLANT, ERR_RPDO_TIMEOUT, ERR_SYNC, STATE_NAMES

    st = res.stats
    names_err = {ERR_RPDO_TIMEOUT: "command watchdog (RPDO timeout)", ERR_HEARTBEAT: "controller heartbeat lost",
                 ERR_PLANT: "plant error", ERR_SYNC: "SYNC from the controller lost"}
    summary = {
        "bus": cfg.bus,
        "controller": cfg.controller,
        "mode": "real-time" if cfg.realtime else "lock-step",
        "rt_priority": st.rt_priority,
        "plant": plant.describe(),
        "step_s": cfg.dt,
        "steps": st.steps,
        "simulated_s": st.steps * cfg.dt,
        "wall_s": st.wall,
        "steps_per_s": st.steps / st.wall if st.wall > 0 else None,
        "real_time_factor": st.steps * cfg.dt / st.wall if st.wall > 0 else None,
        "start_wait_s": st.started_wall,
        "transport_delay": "one SYNC period: the torque held over [t_k, t_k+1) was computed from the sample "
                           "at t_k-1 (RPDO received in cycle k-1, applied at SYNC k; Jacobi coupling)",
        "inject": faults.as_dict(),
        "watchdog_trips": st.watchdog_trips,
        "brake_engaged_at": st.brake_engaged_at,
        "frames_rejected": st.frames_rejected,
        "deadline_misses": st.deadline_misses,
        "frames_rejected_detail": {"malformed": st.rejected_malformed, "out_of_range": st.rejected_out_of_range,
                                   "stale": st.rejected_stale},
        "frames_injected": res.injected,
        "fault": None if st.fault_at is None else {"code": f"0x{st.fault_code:04X}",
                                                   "reason": names_err.get(st.fault_code, "fault"),
                                                   "at": st.fault_at},
        "brake_closed_at": st.brake_closed_at,
        "machine_stopped_at": st.machine_stopped_at,
        "stop_distance_m": st.stop_distance,
        "car_speed_at_fault_m_s": st.car_speed_at_fault,
        "car_excursion_after_fault_m": st.car_excursion,
        "heartbeat_faults": st.heartbeat_faults,
        "heartbeat_gaps": st.heartbeat_gaps,
        "commands_valid": st.commands_valid,
        "commands_missing": st.commands_missing,
        "lockstep_timeouts": st.lockstep_timeouts,
        "frames_received": st.frames_rx,
        "sdo_requests": st.sdo_requests,
        "plant_error": st.plant_error,
        "final_state": STATE_NAMES[int(cols["hil.state"][-1])] if cols else None,
        "step_time_p50_us": _pct(st.step_time, 50) * 1e6 if len(st.step_time) else None,
        "step_time_p99_us": _pct(st.step_time, 99) * 1e6 if len(st.step_time) else None,
        "step_time_max_us": float(np.max(st.step_time)) * 1e6 if len(st.step_time) else None,
        "cycle_time_mean_us": st.wall / st.steps * 1e6 if st.steps else None,
    }
    if cfg.realtime and len(st.sync_jitter):
        summary.update({"sync_jitter_p50_us": _pct(st.sync_jitter, 50) * 1e6,
                        "sync_jitter_p99_us": _pct(st.sync_jitter, 99) * 1e6,
                        "sync_jitter_max_us": float(np.max(st.sync_jitter)) * 1e6})
    if ctl_stats is not None:
        summary["controller_stats"] = ctl_stats
    return summary


def add_trip_figures(summary: dict, cfg, time_, cols: dict):
    """Car travel and speed, peak tension and torque of the record."""
    x = cols.get("car.position")
    v = cols.get("car.velocity")
    if x is not None:
        summary.update({"car_travel_max_m": float(np.max(x) - x[0]), "car_position_final_m": float(x[-1]),
                        "car_speed_max_m_s": float(np.max(np.abs(v))) if v is not None else None})
    if "traction.tension_in" in cols:
        summary["traction_tension_in_max_N"] = float(np.max(cols["traction.tension_in"]))
    summary["motor_torque_peak_Nm"] = float(np.max(np.abs(cols["hil.torque"])))


def write_results(out: Path, cfg, summary: dict, time_, cols: dict, st):
    """results.csv (the record), timing.csv (per-cycle latency), summary.json and (with a record)
    report.md with the trip plots."""
    from ..core.results import write_csv

    out.mkdir(parents=True, exist_ok=True)
    if cols:
        write_csv(out / "results.csv", time_, cols)
    if len(st.step_time):
        # per-cycle latency log: work time SYNC -> plant stepped, and (real time) SYNC lateness
        tcols = {"step_time_us": st.step_time * 1e6}
        if cfg.realtime and len(st.sync_jitter):
            tcols["sync_late_us"] = st.sync_jitter * 1e6
        write_csv(out / "timing.csv", np.arange(len(st.step_time)) * cfg.dt, tcols)
    (out / "summary.json").write_text(json.dumps(summary, indent=2, default=json_default) + "\n",
                                       encoding="utf-8")
    if cols:
        write_report(out, cfg, summary, time_, cols)


def json_default(o):
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    raise TypeError(f"not JSON serialisable: {o!r}")
