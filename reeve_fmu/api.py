"""Scripting API: run a scene or an elevator trip from Python and get numpy arrays (and a pandas
DataFrame when pandas is installed).

    import reeve_fmu
    r = reeve_fmu.simulate("scenes/elevator_2to1.toml", t_end=5.0, overrides={"rope.EA": 3.0e6})
    r["car.position"]            # numpy array, m
    trip = reeve_fmu.cosimulate("scenes/elevator_2to1.toml", load=800.0)
    trip.summary["verdict"], trip.to_pandas()

Units are SI throughout: time s, positions m, speeds m/s, accelerations m/s², forces N, torques N·m,
angles rad, loads kg. Overrides use the keys of `--set` (reeve_fmu.studies.overrides): dotted scene keys
("bodies.car.mass", "rope.EA", "drive.v_max"), drive parameters ("torque.max", "control.Kp",
"sis.enabled") and "load". As keyword arguments, write the dots as double underscores
(`rope__EA=3e6`).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .core.results import TimeSeries


def _overrides(overrides, kw) -> dict:
    out = dict(overrides or {})
    out.update({k.replace("__", "."): v for k, v in kw.items()})
    return out


def simulate(scene, *, t_end: float | None = None, dt: float | None = None, step: float | None = None,
             method: str | None = None, overrides: dict | None = None, **kw) -> TimeSeries:
    """Simulate a scene file as written (its own [drive]) with overrides applied.

    scene      path of a scene TOML file
    t_end      end time [s] (default: scene.t_end)
    dt         output interval [s] (default: scene.output_step)
    step       solver step [s] (default: solver.step); method "gen-alpha" | "radau" | "dop853"
    overrides  {--set key: value}; also as keyword arguments with "__" for "." (rope__EA=3e6);
               "load" [kg] sets the payload of an elevator scene
    """
    from .core.model import build_model
    from .core.plausibility import initial_statics
    from .core.solver import Simulator
    from .studies.overrides import OverrideError, scene_with, split

    scene_sets, drive_sets, load = split(_overrides(overrides, kw))
    if drive_sets:
        raise OverrideError(f"{next(iter(drive_sets))}: drive parameters apply to cosimulate(); simulate runs "
                            f"the scene's own [drive]")
    sc, _ = scene_with(Path(scene), scene_sets)
    if load is not None:
        from .components.elevator import with_load
        sc = with_load(sc, load)
    t_end = sc.t_end if t_end is None else t_end
    dt = sc.output_step if dt is None else dt
    sim = Simulator(build_model(sc), method=method, step=step)
    st = initial_statics(sim)
    res = sim.run(t_end, dt, state=st)
    cols = res.as_dict()
    time_ = np.asarray(cols.pop("time"))
    from .studies.crane import hoist_convention
    from .core.scene import scene_parameters
    from .studies.verdicts import explain, scene_verdicts, worst

    convention = hoist_convention(sc, cols)
    vs = [v.as_dict() for v in scene_verdicts(sc, time_, cols)]
    return TimeSeries(time_, {k: np.asarray(v) for k, v in cols.items()}, info={"scene": sc.name},
                      summary={"verdict": worst(vs), "verdicts": vs, "findings": explain(vs),
                               "motor_sign_convention": convention, "parameters": {"scene": scene_parameters(sc)}})


def cosimulate(scene=None, *, load: float | None = None, landings=None, dwell: float = 3.0,
               step: float = 1e-3, sis: bool = False, overrides: dict | None = None, **kw) -> TimeSeries:
    """An elevator trip: the scene's plant coupled with the electric drive sized from the scene, in
    process (the same models as the FMUs, bit-identical to their co-simulation at the same step).

    scene      elevator scene file (default: the shipped 2:1 scene)
    load       payload in the car [kg] (default: the scene's rated load); the car mass is derived from
               it and the scene's [elevator] table, never from the scene's name
    landings   car positions [m] visited in order (default: lowest, highest, lowest landing)
    dwell      rest between moves [s]
    step       coupling step [s] (<= 2 ms for the ride-quality metrics)
    sis        shaft information system (car-position feedback) for the approach
    overrides  {--set key: value}; also keyword arguments with "__" for "."

    Returns a TimeSeries whose summary holds the trip metrics and the verdicts (studies.verdicts)."""
    from .studies.trip import run_case, run_parameters, summarize_case, trip_case

    case = trip_case(scene, load=load, sequence=landings, dwell=dwell, sets=_overrides(overrides, kw), sis=sis)
    res = run_case(case, step=step)
    s = summarize_case(case, res.time, res.columns, res.info)
    from .studies.verdicts import explain, worst

    s["verdict"] = worst(s["verdicts"])
    s["findings"] = explain(s["verdicts"], s)
    s["scenario"] = {"scene": case.scene.name, "car_load_kg": case.load, "landings_m": list(case.sequence),
                     "dwell_s": case.dwell, "drive_level": int(case.drive_values.get("drive.level", 1)),
                     "drive": {k: v for k, v in case.drive_values.items()}}
    s["parameters"] = run_parameters(case)
    return TimeSeries(np.asarray(res.time), {k: np.asarray(v) for k, v in res.columns.items()}, info=dict(res.info),
                      summary=s)
