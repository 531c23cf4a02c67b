"""Elevator trips of any elevator scene: the case (scene, payload, landings visited, dwell, drive sized
from the scene, overrides), its run (in process or as FMUs) and its summary with verdicts.

`trip_case(scene, load=...)` gives the plant and drive FMU parameter values of a trip; `run_case` runs it
with the in-process monolithic coupling (`fmu.cosim.monolithic`, bit-identical to the FMU
co-simulation at the same step); `summarize_case` computes the trip metrics and the verdicts
(studies.verdicts). The demo (R1 2:1 elevator, rated load, 0 m -> 39 m -> 0 m) is the default case.
"""
from __future__ import annotations

from dataclasses import dataclass, field
import math
from pathlib import Path

import numpy as np

# the demo's reference trip (R1 2:1 elevator, scenes/elevator_2to1.toml)
GROOVE_BETA_DEG = 95.0
GROOVE_GAMMA_DEG = 30.0
WRAP_DEG = 180.0
RATED_LOAD_KG = 1000.0
RATED_SPEED = 1.6       # m/s car
ROPING = 2.0
LANDINGS = (0.0, 39.0)  # m

from .analysis import traction_limits  # noqa: E402

#: DriveParams field of `components.elevator.size_drive` -> drive FMU parameter
SIZED = {"sheave_radius": "machine.sheave_radius", "roping": "machine.roping", "J_ff": "control.J_ff",
         "T_max": "torque.max", "P_max": "torque.power_max", "Kp": "control.Kp", "Ti": "control.Ti",
         "Kpos": "control.Kpos", "v_max": "trip.v_max", "a_max": "trip.a_max", "jerk": "trip.jerk"}


def jerk_of(t, a, cutoff: float = 10.0):
    """Jerk as ISO 18738 takes it: derivative of the acceleration low-passed at 10 Hz."""
    from .analysis import lowpass

    fs = 1.0 / float(t[1] - t[0])
    return np.gradient(lowpass(a, fs, cutoff), t)


# ---------------------------------------------------------------------------------------------- case
@dataclass
class TripCase:
    """A trip of an elevator scene. Positions in m, load in kg, times in s."""
    scene: object                    # core.scene.Scene (overrides applied)
    scene_path: Path | None
    load: float
    sequence: tuple                  # landing positions visited, starting at the first
    dwell: float
    plant_values: dict
    drive_values: dict
    sizing: dict                     # sized drive parameters (FMU names) before overrides
    holding_torques: dict            # landing position -> N m at this load
    scene_sets: dict = field(default_factory=dict)
    drive_sets: dict = field(default_factory=dict)

    @property
    def landings(self) -> tuple:
        return tuple(sorted(set(self.sequence)))

    def describe(self) -> str:
        seq = " -> ".join(f"{x:g}" for x in self.sequence)
        return f"{self.scene.name}, {self.load:g} kg, {seq} m"


_SIZING_CACHE: dict = {}


def sized_drive(scene) -> dict:
    """Drive FMU parameter values sized from the scene (components.elevator.size_drive), cached per scene."""
    from ..components.elevator import elevator_spec, size_drive
    from .verdicts import holding_torque

    key = repr(scene)
    if key not in _SIZING_CACHE:
        spec = elevator_spec(scene)
        ends = (min(spec.landings), max(spec.landings))
        hold = tuple(holding_torque(scene, spec.rated_load, z) for z in ends)
        fields = size_drive(scene, hold)
        _SIZING_CACHE[key] = {SIZED[k]: float(v) for k, v in fields.items() if k in SIZED}
    return dict(_SIZING_CACHE[key])


def trip_case(scene=None, *, load: float | None = None, sequence=None, dwell: float = 3.0, sets=None,
              sis: bool | None = None, level: int = 1) -> TripCase:
    """The trip of `scene` (path or Scene; default the shipped 2:1 scene) with `load` kg in the car
    (default the rated load), visiting the landing positions `sequence` (m; default first, last, first
    landing of [elevator].landings), `dwell` s between moves, drive sized from the scene. `sets`: --set
    overrides {key: value} (studies.overrides); `sis`: shaft information system for the approach."""
    from ..components.elevator import check_load, elevator_spec
    from ..core.scene import Scene
    from ..components.drive import MAX_LANDINGS, MAX_MOVES
    from ..fmu.cosim import default_scene_path
    from .overrides import scene_with, split

    scene_sets, drive_sets, set_load = split(dict(sets or {}))
    path = None
    if scene is None or not isinstance(scene, Scene):
        path = Path(scene) if scene is not None else default_scene_path()
        scene, _ = scene_with(path, scene_sets)
    elif scene_sets:
        raise ValueError("scene overrides need the scene file: pass its path")
    spec = elevator_spec(scene)
    if set_load is not None:
        if load is not None and load != set_load:
            raise ValueError(f"load given twice: {load} and --set load={set_load}")
        load = set_load
    load = check_load(spec, spec.rated_load if load is None else load)
    if sequence is None:
        sequence = (spec.landings[0], spec.landings[-1], spec.landings[0])
    sequence = tuple(float(x) for x in sequence)
    if len(sequence) < 2 or any(not math.isfinite(x) for x in sequence):
        raise ValueError(f"landings: give at least two finite positions (m) to visit, got {sequence!r}")
    if any(a == b for a, b in zip(sequence, sequence[1:])):
        raise ValueError(f"landings {sequence!r}: consecutive landings must differ")
    lo, hi = min(spec.landings), max(spec.landings)
    out = [x for x in sequence if not lo - 1e-9 <= x <= hi + 1e-9]
    if out:
        raise ValueError(f"landings: {out[0]:g} m is outside the travel of {scene.name}, {lo:g} .. {hi:g} m "
                         f"([elevator].landings)")
    car0 = next(b for b in scene.bodies if b.name == spec.car)
    if abs(car0.position[2] - sequence[0]) > 1e-9:
        # the trip starts elsewhere than the scene's car: move car and counterweight there (in the scene
        # file's data too, so that a plant FMU built from it starts there)
        if path is None:
            raise ValueError(f"landings start at {sequence[0]:g} m but the scene's car is at "
                             f"{car0.position[2]:g} m: pass the scene file's path")
        from ..components.elevator import car_at

        moved = {b.name: b.position for b in car_at(scene, sequence[0]).bodies}
        for name in (spec.car, spec.counterweight):
            scene_sets[f"bodies.{name}.position"] = list(moved[name])
        scene, _ = scene_with(path, scene_sets)
    lands = sorted(set(sequence))
    if len(lands) > MAX_LANDINGS or len(sequence) - 1 > MAX_MOVES:
        raise ValueError(f"landings: at most {MAX_LANDINGS} distinct landings and {MAX_MOVES} moves")
    if not (isinstance(dwell, (int, float)) and math.isfinite(dwell) and dwell >= 0):
        raise ValueError(f"dwell = {dwell!r}: must be a time >= 0 s")
    hold = _holding(scene, spec, lands, load)
    sizing = sized_drive(scene)
    dv = dict(sizing)
    dv.update({"drive.level": int(level), "trip.landings": len(lands), "trip.dwell_time": float(dwell),
               "trip.start_landing": lands.index(sequence[0]) + 1})
    for k, x in enumerate(lands, 1):
        dv[f"landing[{k}]"] = x
        dv[f"pretorque[{k}]"] = hold[k - 1]
    for k, x in enumerate(sequence[1:], 1):
        dv[f"trip.target[{k}]"] = lands.index(x) + 1
    if sis is not None:
        dv["sis.enabled"] = 1.0 if sis else 0.0
    dv.update(drive_sets)
    _check_drive(scene, spec, lands, load, hold, dv, drive_sets)
    return TripCase(scene=scene, scene_path=path, load=load, sequence=sequence, dwell=float(dwell),
                    plant_values={"car.load": load}, drive_values=dv, sizing=sizing,
                    holding_torques=dict(zip(lands, hold)), scene_sets=scene_sets, drive_sets=drive_sets)


def _holding(scene, spec, lands, load) -> list:
    """Holding torques [N m] at the landings `lands` with `load` kg (the drive's pre-torque); SceneError
    naming brake.torque when the scene's brake cannot hold the car there (PlausibilityError naming the
    rope when the statics needs a compressed rope)."""
    from ..core.scene import SceneError
    from .verdicts import holding_torque

    hold = [holding_torque(scene, load, x) for x in lands]
    k = max(range(len(lands)), key=lambda i: abs(hold[i]))
    if scene.brake.torque < abs(hold[k]):
        raise SceneError(f"{scene.source}: [brake.torque] = {scene.brake.torque:g} N·m cannot hold the car with "
                         f"{load:g} kg at {lands[k]:g} m: that needs {abs(hold[k]):.1f} N·m at the motor (EN 81-20: "
                         f"the brake holds and stops the car with 125 % of the rated load, "
                         f"{1.25 * spec.rated_load:g} kg)")
    return hold


def _check_drive(scene, spec, lands, load, hold, dv, drive_sets) -> None:
    """ValueError naming torque.max when the drive cannot hold the car at rest with the trip's load or
    the rated load (the drive is sized above both unless torque.max is set)."""
    from .verdicts import holding_torque

    ends = (min(spec.landings), max(spec.landings))
    need = [(abs(h), load, x) for h, x in zip(hold, lands)]
    need += [(abs(holding_torque(scene, spec.rated_load, z)), spec.rated_load, z) for z in ends]
    T, m, x = max(need)
    tmax = float(dv["torque.max"])
    if not tmax >= T:
        how = "--set torque.max" if "torque.max" in drive_sets else "the drive sized from the scene"
        raise ValueError(f"[torque.max] = {tmax:g} N·m ({how}) cannot hold the car with {m:g} kg at {x:g} m, "
                         f"which needs {T:.1f} N·m at the motor")


def run_parameters(case: TripCase, drive_values: dict | None = None) -> dict:
    """Every parameter a trip ran with: the scene after --set with the trip's load in the car mass, the
    plant's values and the drive's (sized from the scene, then --set; default the case's)."""
    from ..components.elevator import with_load
    from ..core.scene import scene_parameters

    return {"scene": scene_parameters(with_load(case.scene, case.load)), "plant": dict(case.plant_values),
            "drive": dict(case.drive_values if drive_values is None else drive_values)}


def run_case(case: TripCase, *, step: float = 1e-3, sis: bool | None = None, progress=None):
    """Run the case in process (Plant + ElectricDrive coupled every `step`, Gauss-Seidel, samples every
    step): a core.results.TimeSeries."""
    from ..fmu import cosim

    dv = dict(case.drive_values)
    if sis is not None:
        dv["sis.enabled"] = 1.0 if sis else 0.0
    return cosim.monolithic(step=step, record_step=step, scene=case.scene, plant_values=case.plant_values,
                            drive_values=dv, progress=progress)


# ------------------------------------------------------------------------------------------- summary
def summarize(t, c, limits, landings=LANDINGS) -> dict:
    """Trip metrics of a record with car.*, motor.torque and traction.traction_ratio columns."""
    from .analysis import trip_summary

    ratio_name = next((n for n in c if n.endswith(".traction_ratio")), None)
    s = trip_summary(t, c["car.position"], c["car.velocity"], c["car.acceleration"], landings=landings,
                     torque=c["motor.torque"], traction_ratio=c[ratio_name] if ratio_name else None,
                     traction_limit=limits["emergency_braking"])
    trips = []
    for r in s["trips"]:
        trips.append({
            "direction": "up" if r["direction"] > 0 else "down",
            "t_start_s": r["t_start_s"], "t_stop_s": r["t_stop_s"], "trip_time_s": r["trip_time_s"],
            "landing_m": r["landing_m"], "stopping_error_mm": r["stopping_error_m"] * 1e3,
            "v_max_m_s": r["v_max_m_s"], "a_max_m_s2": r["a_max_m_s2"], "d_max_m_s2": r["d_max_m_s2"],
            "a95_acceleration_m_s2": r["a95_acc_m_s2"], "a95_deceleration_m_s2": r["a95_dec_m_s2"],
            "jerk_max_m_s3": r["jerk_max_m_s3"], "vibration_pp_max_m_s2": r["vib_pp_max_m_s2"],
            "vibration_pp_a95_m_s2": r["vib_pp_a95_m_s2"],
            "constant_speed_region_s": list(r["cs_region_s"]),
        })
    ratio = float(np.max(c[ratio_name])) if ratio_name else math.nan
    return {
        "trips": trips,
        "trip_time_s": [r["trip_time_s"] for r in trips],
        "max_acceleration_m_s2": max(s["max_acceleration_m_s2"], s["max_deceleration_m_s2"]),
        "max_jerk_m_s3": s["max_jerk_m_s3"],
        "a95_acceleration_m_s2": s["a95_acceleration_m_s2"],
        "a95_deceleration_m_s2": s["a95_deceleration_m_s2"],
        "vibration_pp_max_m_s2": s["vib_pp_max_m_s2"],
        "traction_ratio_max": ratio,
        "traction_limit_emergency_braking": limits["emergency_braking"],
        "traction_limit_loading": limits["loading"],
        "traction_utilisation_vs_emergency_braking": ratio / limits["emergency_braking"],
        "traction_utilisation_vs_loading": ratio / limits["loading"],
        "motor_torque_peak_Nm": s["torque_peak_Nm"],
        "stopping_error_mm": {f"{r['landing_m']:g} m ({r['direction']}, {i + 1})": r["stopping_error_mm"]
                              for i, r in enumerate(trips)},
    }


def summarize_case(case: TripCase, t, c, info: dict | None = None) -> dict:
    """Trip metrics and verdicts of a run of `case` (columns as recorded by the masters)."""
    from .verdicts import trip_verdicts

    limits = traction_limits(case.scene)
    s = summarize(t, c, limits, landings=case.landings)
    s["verdicts"] = [v.as_dict() for v in trip_verdicts(case, t, c, s, limits, info or {})]
    return s
