"""`reeve-fmu demo` (the main job) and `reeve-fmu build`.

demo: builds the plant FMU of an elevator scene (default: fmus/ReevingPlant.fmu of the R1 2:1 elevator,
scenes/elevator_2to1.toml) and fmus/ElectricDrive.fmu if they are missing or stale, sizes the drive from
the scene (studies.trip), and co-simulates a trip with the fmpy master of reeve_fmu.fmu.cosim: by
default the rated load from the lowest landing to the highest, dwell, and back (--scene, --load,
--landings, --dwell, --set change it). The same trip runs once more in process with the shaft
information system (car-position feedback for the approach) for the levelling comparison. Writes
DIR/results.csv (--output-dt thins, --parquet adds results.parquet), results.png, traction.png,
motor.png, levelling.png, summary.json and report.md, and prints the summary table and the verdicts.
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

from .fmu.cosim import fmu_dir


def _rows(summary: dict) -> list:
    rows = [("trip time", " / ".join(f"{x:.2f}" for x in summary["trip_time_s"]), "s")]
    rows += [
        ("max acceleration (|a|, 10 Hz)", f"{summary['max_acceleration_m_s2']:.3f}", "m/s²"),
        ("max jerk (10 Hz)", f"{summary['max_jerk_m_s3']:.3f}", "m/s³"),
        ("A95 acceleration / deceleration",
         f"{summary['a95_acceleration_m_s2']:.3f} / {summary['a95_deceleration_m_s2']:.3f}", "m/s²"),
        ("car vibration, max peak-to-peak (Wk, constant speed)",
         f"{summary['vibration_pp_max_m_s2']:.4f}", "m/s²"),
        ("max traction ratio vs limit e^(fα) (braking / loading)",
         f"{summary['traction_ratio_max']:.3f} vs {summary['traction_limit_emergency_braking']:.3f}"
         f" / {summary['traction_limit_loading']:.3f}", ""),
        ("peak motor torque", f"{summary['motor_torque_peak_Nm']:.1f}", "N·m"),
    ]
    lev = summary.get("levelling")
    for k, v in summary["stopping_error_mm"].items():
        extra = f" (with SIS {lev['with_sis_mm'][k]:+.2f})" if lev and k in lev["with_sis_mm"] else ""
        rows.append((f"stopping error at {k}", f"{v:+.2f}{extra}", "mm"))
    return rows


def print_table(summary: dict) -> None:
    rows = _rows(summary)
    w = max(len(r[0]) for r in rows)
    print()
    for name, val, unit in rows:
        print(f"  {name:<{w}s}  {val} {unit}")
    print()


#: drive outputs recorded in results.csv only when the drive runs its Level 2 (PMSM dq) model
LEVEL2_OUTPUTS = ("motor.current_d", "motor.current_q")


def parameter_groups(parameters: dict) -> dict:
    """report.md's parameter tables."""
    return {"Drive FMU parameters (sized from the scene, then --set)": parameters["drive"],
            "Plant FMU parameters": parameters["plant"],
            "Scene (after --set; the car mass includes the trip's load)": parameters["scene"]}


def _sequence(text):
    if text is None:
        return None
    try:
        return tuple(float(x) for x in str(text).replace(" ", "").split(",") if x)
    except ValueError:
        raise ValueError(f"--landings {text!r}: give car positions in m separated by commas, e.g. 0,39,0") from None


def demo_case(args):
    """The trip case of the demo's options (scene, load, landings, dwell, --set)."""
    from .studies.overrides import parse_sets
    from .studies.trip import trip_case

    return trip_case(getattr(args, "scene", None), load=getattr(args, "load", None),
                     sequence=_sequence(getattr(args, "landings", None)),
                     dwell=float(getattr(args, "dwell", None) if getattr(args, "dwell", None) is not None else 3.0),
                     sets=parse_sets(getattr(args, "set", None)))


def plant_fmu_name(scene_file, scene, name: str | None = None) -> str:
    """The plant FMU's model name, one convention for build, demo and the SSP: `name` when given
    (explicit), the reference name for the shipped reference scene file as it is (ReevingPlant for
    scenes/elevator_2to1.toml, which the SSP cosim/ReevingSystem runs; CranePlant for a crane scene,
    scenes/slewing_crane.toml), Plant_<scene name> for any other scene or a scene changed by --set."""
    from .fmu import cosim
    from .fmu.crane import crane_plant_name, is_crane_scene

    if name:
        return name
    if is_crane_scene(scene):
        return crane_plant_name(scene_file, scene)
    if Path(scene_file).resolve() == cosim.default_scene_path().resolve():
        return cosim.PLANT_NAME
    return "Plant_" + cosim._slug(scene.name)


def _plant_source(case, out: Path):
    """(scene file, plant FMU model name) the plant FMU is built from: the shipped default scene as
    ReevingPlant; another scene, or one changed by --set (written to DIR/scene.toml), under its own name."""
    from .fmu import cosim
    from .studies.overrides import dump_toml, load_scene_data, apply_to_data

    path = Path(case.scene_path)
    if case.scene_sets:
        out.mkdir(parents=True, exist_ok=True)
        data = apply_to_data(load_scene_data(path), case.scene_sets)
        path = out / "scene.toml"
        path.write_text(f"# {case.scene_path} with --set " + ", ".join(
            f"{k}={v!r}" for k, v in case.scene_sets.items()) + "\n" + dump_toml(data), encoding="utf-8")
    return path, plant_fmu_name(path, case.scene)


def _write_stopped(out: Path, case, exc, output_dt) -> None:
    """A co-simulation stopped by a failed step: results.csv up to the last good communication point,
    results.png with the event marked, summary.json with the event (time, cause, FMU log)."""
    from .core.results import plot_overview
    from .studies import report

    res = exc.result
    t, c = res.time, dict(res.columns)
    lines = [ln for ln in str(exc).splitlines() if ln.strip()]
    cause = lines[0] if lines else type(exc).__name__
    out.mkdir(parents=True, exist_ok=True)
    report.write_tables(out, t, c, output_dt=output_dt)
    plot_overview(out / "results.png", t, c, title=f"{case.describe()} (stopped at {exc.time:.3f} s)",
                  event=(exc.time, cause))
    report.write_summary(out, {"scenario": {"scene": case.scene.name, "car_load_kg": case.load,
                                            "landings_m": list(case.sequence)},
                               "event": {"time": exc.time, "cause": cause, "message": str(exc)},
                               "samples": int(len(t)), "t_last": float(t[-1]) if len(t) else None,
                               "verdict": "FAIL", "exit_code": 3})
    print(f"reeve-fmu demo: the co-simulation stopped at t = {exc.time:.3f} s ({cause}); {len(t)} samples "
          f"up to then -> {out}/results.csv, results.png, summary.json", file=sys.stderr)


def _start_sis_run(case, step):
    """The trip with the shaft information system, run in process by a fresh interpreter on the other
    core (studies.trip.run_case): (pool, future), or (None, None) where no process can be started
    (then it runs here, after the co-simulation)."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    from .studies.trip import run_case
    try:
        pool = ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn"))
        return pool, pool.submit(run_case, case, step=step, sis=True)
    except (OSError, RuntimeError):
        return None, None


def _stop_sis_run(sis_run) -> None:
    """The co-simulation failed: the levelling run is not needed; do not wait for it at exit."""
    pool = sis_run[0] if sis_run else None
    if pool is not None:
        for proc in list(getattr(pool, "_processes", {}).values()):
            proc.terminate()
        pool.shutdown(wait=False, cancel_futures=True)


def _sis_result(sis_run, case, step):
    from concurrent.futures.process import BrokenProcessPool

    from .studies.trip import run_case
    pool, future = sis_run
    if future is not None:
        try:
            return future.result()
        except (BrokenProcessPool, OSError):
            pass                        # the second process died (memory, a signal): run it here
        finally:
            pool.shutdown(wait=True)
    return run_case(case, step=step, sis=True)


def _levelling(sis_run, case, step, summary: dict, verdicts: list):
    """The levelling comparison: the trip with the shaft information system (run in the other process)
    summarized into summary["levelling"] and its verdicts added; returns (its time and columns, the
    report's rows per stop)."""
    from .studies.trip import summarize_case
    from .studies.verdicts import levelling_verdicts

    rs = _sis_result(sis_run, case, step)
    ss = summarize_case(case, rs.time, rs.columns, rs.info)
    verdicts[2:2] = [v.as_dict() for v in levelling_verdicts(ss["stopping_error_mm"], " (with SIS)")]
    lev_rows = [(k, summary["stopping_error_mm"][k], ss["stopping_error_mm"].get(k, float("nan")))
                for k in summary["stopping_error_mm"]]
    summary["levelling"] = {
        "motor_encoder_only_mm": summary["stopping_error_mm"], "with_sis_mm": ss["stopping_error_mm"],
        "relevelling_needed_encoder": any(abs(e) > 20 for e in summary["stopping_error_mm"].values()),
        "relevelling_needed_sis": any(abs(e) > 20 for e in ss["stopping_error_mm"].values()),
        "sis": {"resolution_m": case.drive_values.get("sis.resolution", 0.5e-3),
                "delay_s": case.drive_values.get("sis.delay", 2e-3),
                "zone_m": case.drive_values.get("sis.zone", 0.0) or "braking distance",
                "filter_s": case.drive_values.get("sis.filter", 0.2),
                "run": "in process (Plant + ElectricDrive at the same step; the drive FMU has no "
                       "car-position input)"}}
    return (rs.time, rs.columns), lev_rows


def _preload_plotting() -> None:
    """Import matplotlib's pyplot (1.3 s) in a thread: on a cold cache this process then waits for
    the kernels the other process compiles, and the plots at the end no longer pay the import."""
    import threading

    def load():
        try:
            import matplotlib
            matplotlib.use("Agg")
            import matplotlib.pyplot  # noqa: F401
        except Exception:     # noqa: BLE001 - the plots import it again and report what fails
            pass

    threading.Thread(target=load, name="reeve-preload-pyplot", daemon=True).start()


def _in_background(fn):
    """Run fn() in a thread; returns a function that waits for it and gives its result (or raises). Not
    a daemon thread: should the rest of the run fail, the interpreter still waits for it at exit."""
    import threading

    box = {}

    def run():
        try:
            box["result"] = fn()
        except BaseException as exc:   # noqa: BLE001 - handed to the waiting caller
            box["error"] = exc

    th = threading.Thread(target=run, name="reeve-finish-fmus", daemon=False)
    th.start()

    def wait():
        th.join()
        if "error" in box:
            raise box["error"]
        return box["result"]

    return wait


def cli_demo(args) -> int:
    from .fmu import cosim
    from .studies import report

    out = Path(getattr(args, "out", None) or "results")
    step = float(getattr(args, "step", None) or 1e-3)
    if not (0.0 < step <= 2e-3):
        raise ValueError(f"--step {step!r}: the communication step must be in (0, 2 ms]; the ride-quality "
                         f"metrics (ISO 18738 style, Wk weighting) need samples at >= 500 Hz, and beyond "
                         f"2 ms the co-simulation error grows quickly (docs/cosim.md)")
    output_dt = getattr(args, "output_dt", None)
    report.thin_index([0.0, step], output_dt)          # validate before the run
    t0 = time.perf_counter()
    from .fmu.kernels import cache_is_cold, compile_beside
    beside = None
    if cache_is_cold():
        print("compiling the model's kernels for this machine (the first run with these sources: about "
              "half a minute on 2 cores; later runs and the FMUs load them)")
        # the stepping kernel compiles on the other core while this process compiles the statics
        beside = compile_beside(getattr(args, "scene", None) or cosim.default_scene_path())
    # imported after the second process has started: scipy.signal alone takes 1.5 s
    from .components.drive import SIS_PARAMETERS, trip_end_time
    from .fmu.master import CosimError
    from .studies.analysis import traction_limits
    from .studies.trip import run_case, run_parameters, summarize_case
    from .studies.verdicts import explain, print_verdicts, worst

    case = demo_case(args)
    if beside is not None:
        _preload_plotting()     # in a thread, while the FMUs build and their warm-ups wait for kernels
        # the drive's kernel now, while the other process still compiles the stepping kernel: the
        # drive FMU's warm-up then loads it instead of compiling it after the plant's is done
        from .components.drive import ElectricDrive
        ElectricDrive().warm_up()
    scene_file, name = _plant_source(case, out)
    # the FMUs are co-simulated as soon as they are built; their precompiled kernels (a warm-up run of
    # each, in subprocesses) are added while this process writes the results (fmus.finish)
    fmus = cosim.prepare_fmus(fmu_dir(), scene=scene_file, name=name, rebuild=bool(getattr(args, "rebuild", False)))
    plant_fmu, drive_fmu = fmus.paths
    if beside is not None:
        beside.wait()
    drive_values = {k: v for k, v in case.drive_values.items() if k not in SIS_PARAMETERS}
    t_end = trip_end_time(case.drive_values)
    pre = [case.holding_torques[x] for x in case.landings]
    print(f"{case.describe()}: {t_end:.2f} s at a {step * 1e3:g} ms communication step (pre-torque "
          + " / ".join(f"{p:.1f}" for p in pre) + " N·m from the plant's holding torque; drive sized: "
          f"torque.max {drive_values['torque.max']:.0f} N·m, torque.power_max "
          f"{drive_values['torque.power_max'] / 1e3:.1f} kW)")
    # the levelling comparison's in-process trip runs in a second process while the FMUs co-simulate
    sis_run = _start_sis_run(case, step) if getattr(args, "levelling", "both") != "encoder" else None
    print("instantiating the FMUs")
    bar = progress = None
    if not getattr(args, "no_progress", False):
        from tqdm import tqdm

        bar = tqdm(total=round(t_end, 3), unit="s", bar_format="{l_bar}{bar}| {n:.1f}/{total:.1f} s sim "
                                                                "[{elapsed}<{remaining}]")

        def progress(t):
            bar.n = round(min(t, t_end), 3)
            bar.refresh()
    try:
        res = cosim.cosimulate(plant_fmu, drive_fmu, step=step, t_end=t_end, plant_values=case.plant_values,
                               drive_values=drive_values, progress=progress)
    except BaseException as exc:
        _stop_sis_run(sis_run)
        if isinstance(exc, CosimError):     # the FMUs are sound: complete them
            fmus.finish()
            if exc.result is not None:      # keep what was computed, exit 3
                _write_stopped(out, case, exc, output_dt)
        else:
            fmus.discard()
        raise
    finally:
        if bar is not None:
            bar.close()
    finishing = _in_background(fmus.finish)
    t, c = res.time, res.columns
    summary = summarize_case(case, t, c, res.info)
    verdicts = list(summary.pop("verdicts"))
    sis, lev_rows = _levelling(sis_run, case, step, summary, verdicts) if sis_run is not None else (None, None)
    out.mkdir(parents=True, exist_ok=True)
    order = []
    for n in res.info["plant_outputs"]:
        order.append(n)
        if n == "motor.speed":
            order.append("motor.torque")
    level = int(drive_values.get("drive.level", 1))
    order += [n for n in ("brake.command",) + cosim.DRIVE_RECORD if n not in order and n in c
              and (level == 2 or n not in LEVEL2_OUTPUTS)]
    files = report.write_tables(out, t, {n: c[n] for n in order}, output_dt=output_dt,
                                parquet=bool(getattr(args, "parquet", False)))
    limits = traction_limits(case.scene)
    stops = [(r["t_stop_s"], r["landing_m"]) for r in summary["trips"]]
    pngs = report.plot_trip(out, t, c, limits=limits, title=f"{case.describe()}, co-simulation (plant + "
                            f"drive FMUs, {step * 1e3:g} ms)", stops=stops, sis=sis)
    plant_fmu, drive_fmu = finishing()
    scenario = {"scene": case.scene.name, "scene_file": str(scene_file), "car_load_kg": case.load,
                "landings_m": list(case.sequence), "dwell_s": case.dwell,
                "pretorque_Nm": pre, "drive_level": level, "communication_step_s": step,
                "drive_sizing": case.sizing, "overrides": {**case.scene_sets, **case.drive_sets},
                "drive_values": dict(drive_values), "plant_values": dict(case.plant_values),
                "scheme": res.info["scheme"], "t_end_s": res.info["t_end_s"],
                "plant_fmu": str(plant_fmu), "drive_fmu": str(drive_fmu)}
    parameters = run_parameters(case, drive_values)      # (the drive FMU gets no sis.* values)
    summary = {
        "scenario": scenario,
        "parameters": parameters,
        **summary,
        "verdict": worst(verdicts),
        "verdicts": verdicts,
        "findings": explain(verdicts, summary),
        "cosim": {"steps": res.info["steps"], "loop_wall_s": res.info["loop_wall_s"],
                  "real_time_factor": res.info["rtf"], "total_wall_s": time.perf_counter() - t0,
                  "first_step_wall_s": res.info["first_step_wall_s"],
                  "real_time_factor_after_first_step": res.info["rtf_after_first_step"],
                  "fmu_warnings": res.info["fmu_warnings"],
                  **{k: res.info[k] for k in cosim.MONITOR_FIELDS}},
    }
    report.write_summary(out, summary)
    metrics = [(a, b, u) for a, b, u in _rows(summary)]
    report.write_report(out, f"Trip study: {case.describe()}", {k: v for k, v in scenario.items()
                                                                if k not in ("drive_sizing",)},
                        metrics, verdicts, pngs, lev_rows, command="reeve-fmu demo",
                        findings=summary["findings"], parameters=parameter_groups(parameters))
    print_table(summary)
    print_verdicts(verdicts, summary=summary)
    first = res.info["first_step_wall_s"]
    print(f"co-simulation: {res.info['steps']} steps in {res.info['loop_wall_s']:.2f} s "
          f"({res.info['rtf']:.1f}x real time"
          + (f"; {res.info['rtf_after_first_step']:.1f}x after the first step, which took {first:.1f} s "
             f"to load/compile the kernels)" if first > 0.5 else ")"))
    print(cosim.monitor_line(res.info))
    print(f"-> {out}/" + ", ".join(p.name for p in files) + ", " + ", ".join(pngs)
          + ", summary.json, report.md")
    return 0


def _build_crane(dest: Path, scene: Path, name: str, standalone: bool = False, fmi_version: int = 2) -> int:
    """A crane scene (a revolute joint and a hoist drive): the crane plant FMU `name`, CraneDrive.fmu
    and DEST/<name>.drive.json, the drive parameters sized from the scene."""
    import json

    from .fmu.crane import build_crane_fmus

    t0 = time.perf_counter()
    plant, drive, values = build_crane_fmus(dest, scene, name=name, standalone=standalone,
                                            fmi_version=fmi_version)
    print(f"built {plant} and {drive} ({time.perf_counter() - t0:.1f} s)")
    p = dest / f"{name}.drive.json"
    p.write_text(json.dumps({"drive": values}, indent=1) + "\n", encoding="utf-8")
    print(f"drive parameters sized for {scene.name} (start values for {drive.name}) -> {p}")
    return 0


def cli_build(args) -> int:
    """Build the plant FMU of a scene (with --set applied) and the drive FMU (a crane scene: the crane
    plant and crane drive FMUs, `_build_crane`), and write DEST/<name>.drive.json, the drive parameters
    sized from the scene (start values to give the drive FMU, whose built-in defaults are those of the
    R1 2:1 elevator or of the slewing crane). The plant FMU is named by `plant_fmu_name`: only the
    reference scene, or an explicit --name, writes ReevingPlant.fmu (CranePlant.fmu for cranes)."""
    import json

    from .components.drive import SIS_PARAMETERS
    from .fmu import cosim
    from .studies.overrides import apply_to_data, dump_toml, load_scene_data, parse_sets, scene_with, split

    fmi_version = int(getattr(args, "fmi", None) or 2)
    dest = Path(getattr(args, "dest", None) or ("fmus" if fmi_version == 2 else "fmus/fmi3"))
    standalone = bool(getattr(args, "standalone", False))
    scene = Path(getattr(args, "scene", None) or cosim.default_scene_path())
    scene_sets, drive_sets, load = split(parse_sets(getattr(args, "set", None)))
    sc, _ = scene_with(scene, scene_sets)
    # a changed reference scene is another plant: it never takes the reference name implicitly
    name = plant_fmu_name(scene if not scene_sets else dest / "changed.toml", sc, getattr(args, "name", None))
    from .fmu.crane import CRANE_NAME, CRANE_REFERENCE_SCENE, is_crane_scene
    crane = is_crane_scene(sc)
    reference = (CRANE_NAME, CRANE_REFERENCE_SCENE) if crane else (cosim.PLANT_NAME, cosim.DEFAULT_SCENE)
    if name == reference[0] and (scene_sets or plant_fmu_name(scene, sc) != reference[0]):
        print(f"note: --name {name} replaces the reference plant FMU (scene {reference[1]}"
              + ("" if crane else ", run by the SSP cosim/ReevingSystem") + f") with {sc.name}")
    if scene_sets:
        dest.mkdir(parents=True, exist_ok=True)
        path = dest / f"{name}.scene.toml"
        path.write_text(dump_toml(apply_to_data(load_scene_data(scene), scene_sets)), encoding="utf-8")
        scene = path
    if crane:
        return _build_crane(dest, scene, name, standalone, fmi_version)
    plant, drive = cosim.prepare_fmus(dest, scene, name, rebuild=True, standalone=standalone,
                                      fmi_version=fmi_version).finish()
    if "elevator" in sc.extra:
        from .studies.trip import trip_case

        case = trip_case(scene, load=load, sets=drive_sets)
        vals = {k: v for k, v in case.drive_values.items() if k not in SIS_PARAMETERS}
        p = dest / f"{name}.drive.json"
        p.write_text(json.dumps({"plant": {"car.load": case.load}, "drive": vals}, indent=1) + "\n", encoding="utf-8")
        print(f"drive parameters sized for {sc.name} (start values for {drive.name}) -> {p}")
    return 0
