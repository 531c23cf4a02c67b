"""Co-simulation of the reeving plant with the electric drive: FMU build, fmpy master, monolithic reference.

Three ways to run the same closed loop (docs/cosim.md):

* `cosimulate(plant_fmu, drive_fmu, ...)`   an fmpy `FMU2Slave` master. The two FMUs exchange
  `motor.speed`/`motor.angle` (plant -> drive) and `motor.torque`/`brake.command` (drive -> plant)
  every communication step `step`. Scheme "gauss-seidel" (default): the drive steps first with the
  plant's measurement at t, then the plant steps holding the drive's new torque; "jacobi": both step
  in parallel with the values of t (what libcosim's fixed-step algorithm does).
* `monolithic(...)`   the same `Plant` and `ElectricDrive` objects in this process without FMI,
  exchanging at a much finer step (default 0.1 ms, Gauss-Seidel): the reference of the
  co-simulation accuracy check.
* cosim/ReevingSystem/SystemStructure.ssd   the SSP description of the same system, run by libcosim
  (cosim/run_libcosim.py).

The plant and drive FMU entries (fmus/reeve_plant_slave.py, fmus/reeve_drive_slave.py) build their
models with `make_plant`/`make_drive` of reeve_fmu.components (plant, drive), as `monolithic` does, so
the FMUs and the in-process reference are the same code with the same parameter mapping.

Car load: an elevator scene declares in its [elevator] table the rated load and `car_load`, the payload
its car body's mass includes (reeve_fmu.components.elevator). The plant FMU's parameter `car.load` is the
payload on top of the *empty* car (mass - car_load); its default is the rated load. A scene without an
[elevator] table is taken as written: `car.load` (default 0) adds to its car body's mass. Every helper
here takes the payload explicitly; nothing depends on the scene's name.

This module imports only numpy (plus reeve_fmu) at import time: it is vendored into the FMUs.
"""
from __future__ import annotations

import json
import math
import os
import tempfile
import time
from pathlib import Path
from typing import Callable, Iterable, Mapping, Optional, Sequence

from ..core.results import TimeSeries
from . import master
from .master import SCHEMES, CosimError, FmuUnit, time_grid

PLANT_NAME = "ReevingPlant"
DRIVE_NAME = "ElectricDrive"
PLANT_CONFIG = "reeve_plant.json"     # resource of the plant FMU (see plant_config)
PLANT_SCENE = "scene.toml"            # resource of the plant FMU: the scene it was built from
DEFAULT_SCENE = "elevator_2to1.toml"

# ------------------------------------------------------------------------------------------------
# the plant FMU: output declarations and configuration
# ------------------------------------------------------------------------------------------------
def plant_output_specs(output_names: Sequence[str], sheave_names: Iterable[str]) -> list[dict]:
    """FMI declaration of each plant output: unit, declaredType, derivative, description and the
    direct feed-through from motor.torque.

    Feed-through (measured, tests/fmu/test_plant_fmu.py::test_declared_dependencies_match_the_plant):
    with the torque held over the step, body accelerations and the rope forces at the sheaves (and
    the traction ratio) react to a torque change within an arbitrarily short step; positions, speeds,
    angles, the hitch forces, the brake torque and engagement do not (they integrate it). No output
    depends directly on brake.command (the brake engages with a lag)."""
    sheaves = set(sheave_names)
    specs = []
    seen = set()
    for name in output_names:
        if name == "motor.torque":
            continue  # the input of the same name
        obj, _, q = name.partition(".")
        spec = {"name": name, "unit": None, "type": None, "derivative_of": None, "display": None,
                "depends": False, "description": None}
        if q == "position":
            spec.update(type="Position", display="mm", description=f"{obj} position (up positive)")
        elif q == "velocity":
            spec.update(type="Velocity", description=f"{obj} velocity (up positive)")
            if f"{obj}.position" in seen:
                spec["derivative_of"] = f"{obj}.position"
        elif q == "acceleration":
            spec.update(type="Acceleration", depends=True, description=f"{obj} acceleration (up positive)")
            if f"{obj}.velocity" in seen:
                spec["derivative_of"] = f"{obj}.velocity"
        elif q == "angle":
            spec.update(type="Angle", description=f"{obj} rotation angle (positive: rope moves along "
                                                  f"its route; motor: car up)")
        elif q == "speed":
            spec.update(type="AngularVelocity", display="rpm", description=f"{obj} angular speed")
            if f"{obj}.angle" in seen:
                spec["derivative_of"] = f"{obj}.angle"
        elif q in ("tension_in", "tension_out"):
            side = "entry" if q == "tension_in" else "exit"
            spec.update(type="Force", depends=obj in sheaves,
                        description=f"rope force at the {side} tangent point of {obj} (all parallel ropes)")
        elif q in ("tension_start", "tension_end"):
            spec.update(type="Force", description=f"rope force at the {q[8:]} of rope {obj} "
                                                  f"(all parallel ropes)")
        elif q == "traction_ratio":
            spec.update(unit="1", depends=True, description=f"larger over smaller rope force at {obj} "
                                                            f"(compare with e^(f alpha))")
        elif name == "brake.torque":
            spec.update(type="Torque", description="torque transmitted by the machine brake")
        elif name == "brake.engaged":
            spec.update(unit="1", description="brake engagement 0 (open) .. 1 (closed)")
        else:
            spec.update(unit="1", description=name)
        seen.add(name)
        specs.append(spec)
    return specs


def checked_scene(scene_path):
    """The scene an FMU is built from; a physically impossible scene fails the build, not the FMU's
    initialization."""
    from ..core.plausibility import check_or_raise
    from ..core.scene import load_scene

    scene = load_scene(scene_path)
    check_or_raise(scene)
    return scene


def fmu_config(fmt: str, name: str, scene, resource: str, **fields) -> dict:
    """The JSON configuration a plant FMU carries: format, model name, the scene's resource file, the
    scene's name and description, then `fields`."""
    return {"format": fmt, "name": name, "scene": resource, "scene_name": scene.name,
            "scene_description": getattr(scene, "description", "") or "", **fields}


def plant_config(scene_path, name: str = PLANT_NAME) -> dict:
    """The JSON configuration the plant FMU carries (resources/reeve_plant.json)."""
    from ..components.drive import trip_end_time
    from ..components.plant import empty_car_scene, plant_defaults, plant_scene, scene_load
    from ..core.model import build_model

    scene = checked_scene(scene_path)
    model = build_model(plant_scene(empty_car_scene(scene)))
    return fmu_config("reeve_fmu.plant_fmu/1", name, scene, PLANT_SCENE, scene_payload=scene_load(scene),
                      parameters=plant_defaults(scene), stop_time=max(float(scene.t_end), trip_end_time()),
                      outputs=plant_output_specs(model.output_names, [s.name for s in scene.sheaves]))


# ------------------------------------------------------------------------------------------------
# building the FMUs
# ------------------------------------------------------------------------------------------------

def repo_root() -> Path:
    return Path(__file__).resolve().parents[2]

def fmu_dir() -> Path:
    """Where the demo keeps its FMUs: $REEVE_FMU_FMUS, else fmus/ of the source checkout."""
    env = os.environ.get("REEVE_FMU_FMUS")
    if env:
        return Path(env)
    return repo_root() / "fmus"


def entry_script(kind: str) -> Path:
    """fmus/reeve_plant_slave.py or fmus/reeve_drive_slave.py of this checkout."""
    p = repo_root() / "fmus" / f"reeve_{kind}_slave.py"
    if not p.is_file():
        raise FileNotFoundError(f"FMU entry script {p} not found: building FMUs needs a source checkout "
                                f"of reeve_fmu (pip install -e .)")
    return p


def default_scene_path() -> Path:
    from ..core.scene import default_scene

    return Path(default_scene(DEFAULT_SCENE))


def _slug(name: str) -> str:
    s = "".join(c.lower() if c.isalnum() else "_" for c in name).strip("_")
    return s or "plant"


def _plant_entry(name: str, workdir: Path) -> Path:
    """Entry script for a plant FMU called `name`: the shipped one for the default name, else a copy
    with a unique module name (two FMUs sharing an entry module name clash in one process)."""
    entry = entry_script("plant")
    if name == PLANT_NAME:
        return entry
    target = workdir / f"reeve_plant_{_slug(name)}_slave.py"
    target.write_bytes(entry.read_bytes())
    return target


def _check_model_name(name: str) -> None:
    if not name or not name.isidentifier():
        raise ValueError(f"FMU model name {name!r} must be a valid identifier (it names the binary)")
    if name == DRIVE_NAME:
        raise ValueError(f"the plant FMU cannot be called {DRIVE_NAME!r} (that is the drive FMU)")


def plant_fmu_model(plant_fmu) -> tuple:
    """(Scene, declared car_load) a built plant FMU carries (resources/scene.toml, reeve_plant.json)."""
    import zipfile

    from ..core.scene import loads_scene

    with zipfile.ZipFile(plant_fmu) as zf:
        cfg = json.loads(zf.read(f"resources/{PLANT_CONFIG}").decode("utf-8"))
        text = zf.read(f"resources/{cfg['scene']}").decode("utf-8")
    return loads_scene(text, f"{plant_fmu}!resources/{cfg['scene']}"), float(cfg["scene_payload"])


def plant_build_inputs(scene=None, name: str = PLANT_NAME, workdir: Optional[Path] = None):
    """(entry script, resources) of the plant FMU for `scene` (path) and model `name`."""
    _check_model_name(name)
    scene_path = Path(scene) if scene is not None else default_scene_path()
    if not scene_path.is_file():
        raise FileNotFoundError(f"scene file {scene_path} not found")
    workdir = Path(workdir or tempfile.mkdtemp(prefix="reeve_plant_entry_"))
    cfg = plant_config(scene_path, name)
    resources = {PLANT_SCENE: scene_path.read_bytes(),
                 PLANT_CONFIG: (json.dumps(cfg, indent=1) + "\n").encode()}
    return _plant_entry(name, workdir), resources


def _start_plant_build(dest: Path, scene, name: str, force: bool, standalone: bool = False,
                       fmi_version: int = 2):
    """The plant FMU's PendingFmu (build.start_fmu_build), or its path when up to date and not force."""
    from .build import fmu_is_stale, start_fmu_build

    with tempfile.TemporaryDirectory(prefix="reeve_plant_entry_") as work:
        entry, res = plant_build_inputs(scene, name, Path(work))
        path = dest / f"{name}.fmu"
        if not force and not fmu_is_stale(path, entry, res):
            return path
        return start_fmu_build(entry, dest, resources=res, standalone=standalone, fmi_version=fmi_version)


def _start_drive_build(dest: Path, force: bool, standalone: bool = False, fmi_version: int = 2):
    from .build import NUMBA, NUMPY, fmu_is_stale, start_fmu_build

    entry = entry_script("drive")
    path = dest / f"{DRIVE_NAME}.fmu"
    if not force and not fmu_is_stale(path, entry):
        return path
    return start_fmu_build(entry, dest, requirements=(NUMPY, NUMBA), standalone=standalone,   # no TOML read
                           fmi_version=fmi_version)


def _finished(job) -> tuple[Path, bool]:
    return (job, False) if isinstance(job, Path) else (job.finish(), True)


def build_plant_fmu(dest="fmus", scene=None, name: str = PLANT_NAME, *, force: bool = True,
                    standalone: bool = False, fmi_version: int = 2) -> tuple[Path, bool]:
    """Build (or, with force=False, reuse if up to date) the plant FMU; returns (path, built?).
    standalone: the FMU carries its interpreter; fmi_version 3: an FMI 3.0 FMU (build_fmu)."""
    return _finished(_start_plant_build(Path(dest), scene, name, force, standalone, fmi_version))


def build_drive_fmu(dest="fmus", *, force: bool = True, standalone: bool = False,
                    fmi_version: int = 2) -> tuple[Path, bool]:
    return _finished(_start_drive_build(Path(dest), force, standalone, fmi_version))


def prepare_fmus(dest="fmus", scene=None, name: str = PLANT_NAME, rebuild: bool = False,
                 log: Optional[Callable[[str], None]] = print, *, standalone: bool = False,
                 fmi_version: int = 2):
    """The plant and drive FMUs in `dest`, rebuilt (side by side) if missing, stale or `rebuild`, up to
    their precompiled kernels: build.FmuBuilds, whose `paths` (plant, drive) load at once and whose
    finish() completes them."""
    from .build import start_builds

    dest = Path(dest)
    return start_builds([lambda: _start_plant_build(dest, scene, name, rebuild, standalone, fmi_version),
                         lambda: _start_drive_build(dest, rebuild, standalone, fmi_version)], log)


def ensure_fmus(dest="fmus", scene=None, name: str = PLANT_NAME, rebuild: bool = False,
                log: Optional[Callable[[str], None]] = print) -> tuple[Path, Path]:
    """Build the plant and drive FMUs into `dest` if missing, stale or `rebuild`; return their paths.
    The two builds run side by side (each build's warm-up is a subprocess that may compile kernels:
    two cores, two compiles)."""
    plant, drive = prepare_fmus(dest, scene, name, rebuild, log).finish()
    return plant, drive


# ------------------------------------------------------------------------------------------------
# results
# ------------------------------------------------------------------------------------------------
#: drive outputs recorded by the masters (after motor.torque and brake.command)
DRIVE_RECORD = ("car.position_ref", "car.velocity_ref", "car.acceleration_ref",
                "motor.speed_ref", "drive.torque_ref", "motor.current_d", "motor.current_q")
PLANT_EXCHANGE = ("motor.speed", "motor.angle")        # plant -> drive
DRIVE_EXCHANGE = ("motor.torque", "brake.command")     # drive -> plant


#: the elevator's connections (source, target): the plant's measurement to the drive, the drive's torque
#: and brake command to the plant
CONNECTIONS = tuple((f"plant.{v}", f"drive.{v}") for v in PLANT_EXCHANGE) + \
    tuple((f"drive.{v}", f"plant.{v}") for v in DRIVE_EXCHANGE)


# ------------------------------------------------------------------------------------------------
# coupling monitor
# ------------------------------------------------------------------------------------------------
class CosimInstability(CosimError):
    """The coupling monitor detected an unstable or implausible co-simulation (on_instability="raise")."""


class CouplingMonitor:
    """Instability/plausibility monitor of the torque-speed power bond exchanged every communication
    step (docs/hard-cases.md, "Large communication steps"). Criteria, checked after every step:

    * ``non-finite``: an exchanged value (torque, brake command, speed, angle) is NaN or +-Inf.
    * ``torque chatter``: RMS over a sliding window (`chatter_window` s, >= 4 steps) of the period-2
      component of the exchanged torque, |tau_(k+1) - 2 tau_k + tau_(k-1)| / 4, above
      `chatter_limit` x `torque_scale` (the drive's torque limit). A smooth torque sampled at step h has
      a second difference ~ tau'' h^2 (a ramp corner: slope x h); a loop that is unstable at the
      sampling rate alternates from step to step, and its second difference is 4x its amplitude.
    * ``energy residual``: energy created by the coupling, the standard co-simulation power-bond
      residual. Over a step the plant receives exactly tau_p (theta_(k+1) - theta_k) (its torque is
      held); the drive delivered tau_d omega_k h with the speed it was given. Their difference summed
      over a sliding window (`energy_window` s) above `energy_limit` x the energy transmitted in the
      window (sum |tau_p dtheta|) + `energy_floor` x `torque_scale` x 1 rad. This also catches slow
      (sub-Nyquist) oscillations that the chatter criterion attenuates.

    Every detection is an *episode* (start, end, criterion, peak value); the first one is reported with
    time, criterion, value and threshold. Thresholds are calibrated on the R1 round trip at 1-20 ms
    (benchmarks/large_steps.py): see the table in docs/hard-cases.md.
    """

    def __init__(self, step: float, torque_scale: Optional[float] = None, *, chatter_window: float = 0.05,
                 chatter_limit: float = 0.05, energy_window: float = 0.5, energy_limit: float = 0.02,
                 energy_floor: float = 0.005):
        self.h = float(step)
        self.torque_scale = float(torque_scale) if torque_scale else None
        self.chatter_limit = chatter_limit
        self.energy_limit = energy_limit
        self.energy_floor = energy_floor
        self.nc = max(4, int(round(chatter_window / step)))
        self.ne = max(4, int(round(energy_window / step)))
        self._c2 = [0.0] * self.nc          # ring buffer of the squared period-2 component
        self._er = [0.0] * self.ne          # ring buffers of the residual and the transmitted energy
        self._et = [0.0] * self.ne
        self._sc2 = self._ser = self._set = 0.0
        self._k = 0
        self._tau1 = self._tau2 = None
        self._tau_max = 0.0
        self.residual_J = 0.0               # total energy created by the coupling
        self.transmitted_J = 0.0            # total sum |tau_p dtheta|
        self._chat2_max = 0.0               # peak (chatter RMS / torque scale)^2
        self._chat2_lim = chatter_limit * chatter_limit
        self.energy_ratio_max = 0.0         # peak window residual / its threshold
        self.episodes: list = []
        self._open: dict = {}               # criterion -> open episode
        self.merge_gap = 1.0                # s: a detection this soon after an episode continues it

    @property
    def stable(self) -> bool:
        return not self.episodes

    @property
    def first(self) -> Optional[dict]:
        return min(self.episodes, key=lambda e: e["t_start_s"]) if self.episodes else None

    def _flag(self, crit: str, t: float, value: float, limit: float, unit: str) -> Optional[dict]:
        t, value, limit = float(t), float(value), float(limit)
        e = self._open.get(crit)
        if e is None:
            last = [x for x in self.episodes if x["criterion"] == crit]
            if last and t - last[-1]["t_end_s"] <= self.merge_gap:     # the same episode resumes
                self._open[crit] = e = last[-1]
        if e is None:
            e = {"criterion": crit, "t_start_s": t, "t_end_s": t, "value": value, "threshold": limit,
                 "peak": value, "t_peak_s": t, "unit": unit}
            self._open[crit] = e
            self.episodes.append(e)
            return e
        e["t_end_s"] = t
        if value > e["peak"]:
            e["peak"], e["t_peak_s"] = value, t
        return None

    def _close(self, crit: str) -> None:
        self._open.pop(crit, None)

    def update(self, t: float, tau_plant: float, tau_drive: float, brake: float, omega_in: float,
               theta0: float, theta1: float) -> Optional[dict]:
        """One communication step ending at `t`: `tau_plant` the torque the plant held, `tau_drive` the
        drive's new output, `omega_in` the speed the drive was given, theta0/theta1 the plant's angle
        at the start/end of the step. Returns the new episode if one starts at this step.
        It runs inside the master's step loop, on every step: scalar arithmetic only."""
        s = tau_plant + tau_drive + brake + omega_in + theta0 + theta1
        if s - s != 0.0:                    # NaN or +-Inf somewhere
            self._k += 1
            return self._flag("non-finite", t, math.nan, 0.0, "")
        k = self._k
        ts = self.torque_scale
        if ts is None:
            a = abs(tau_drive)
            if a > self._tau_max:
                self._tau_max = a
            ts = self._tau_max
        i = k % self.nc
        t1 = self._tau1
        if k >= 2:
            c = 0.25 * (tau_drive - 2.0 * t1 + self._tau2)
            c *= c
        else:
            c = 0.0
        buf = self._c2
        self._sc2 += c - buf[i]
        buf[i] = c
        if i == self.nc - 1:                # no drift of the running sum
            self._sc2 = math.fsum(buf)
        self._tau2, self._tau1 = t1, tau_drive
        dth = theta1 - theta0
        r = tau_plant * dth - tau_drive * omega_in * self.h
        e = abs(tau_plant * dth)
        self.residual_J += r
        self.transmitted_J += e
        j = k % self.ne
        er, et = self._er, self._et
        self._ser += r - er[j]
        self._set += e - et[j]
        er[j] = r
        et[j] = e
        if j == self.ne - 1:
            self._ser, self._set = math.fsum(er), math.fsum(et)
        self._k = k + 1
        if ts <= 0.0 or k < 2:
            return None
        new = None
        c2 = self._sc2 / (self.nc * ts * ts)          # (chatter RMS / torque scale)^2
        if c2 > self._chat2_max:
            self._chat2_max = c2
        if c2 > self._chat2_lim:
            new = self._flag("torque chatter", t, math.sqrt(c2), self.chatter_limit, "of the torque scale")
        elif self._open:
            self._close("torque chatter")
        q = self._ser / (self.energy_limit * self._set + self.energy_floor * ts)
        if q > self.energy_ratio_max:
            self.energy_ratio_max = q
        if q > 1.0:
            new = self._flag("energy residual", t, self._ser, self._ser / q, "J") or new
        elif self._open:
            self._close("energy residual")
        return new

    @property
    def chatter_max(self) -> float:
        """Peak chatter RMS / torque scale so far."""
        return math.sqrt(self._chat2_max)

    @staticmethod
    def describe(e: dict, step: float, scheme: str) -> str:
        if e["criterion"] == "non-finite":
            what = "an exchanged value is not finite"
        elif e["criterion"] == "torque chatter":
            what = (f"torque chatter {e['value'] * 100:.1f} % of the torque scale (RMS of the step-to-step "
                    f"alternating component; limit {e['threshold'] * 100:.0f} %)")
        else:
            what = (f"energy residual {e['value']:.1f} J created by the coupling in the last window "
                    f"(limit {e['threshold']:.1f} J)")
        return (f"co-simulation coupling unstable at t = {e['t_start_s']:.3f} s "
                f"({scheme}, step {step * 1e3:g} ms): {what}; use a smaller communication step "
                f"(docs/hard-cases.md, 'Large communication steps')")

    def report(self, scheme: str) -> dict:
        """The result fields: coupling_stable, instability_detected_at, the first episode's message, all
        episodes and the monitored figures."""
        f = self.first
        return {"coupling_stable": f is None,
                "instability_detected_at": None if f is None else f["t_start_s"],
                "instability": None if f is None else dict(f, message=self.describe(f, self.h, scheme)),
                "instability_episodes": [dict(e) for e in self.episodes],
                "coupling_energy_residual_J": float(self.residual_J),
                "transmitted_energy_J": float(self.transmitted_J),
                "torque_chatter_max": float(self.chatter_max),
                "energy_residual_max_ratio": float(self.energy_ratio_max),
                "monitor_torque_scale_Nm": float(self.torque_scale or self._tau_max)}


def _on_detection(mon: CouplingMonitor, ep: dict, scheme: str, on_instability: str) -> bool:
    """Log the detection; raise for on_instability="raise"; return True to stop the run."""
    import logging

    msg = CouplingMonitor.describe(ep, mon.h, scheme)
    logging.getLogger("reeve_fmu.fmu.cosim").warning(msg)
    if on_instability == "raise":
        raise CosimInstability(msg)
    return on_instability == "stop"


ON_INSTABILITY = ("warn", "stop", "raise")
#: result fields of the monitor (CouplingMonitor.report), e.g. for a summary.json
MONITOR_FIELDS = ("coupling_stable", "instability_detected_at", "instability", "instability_episodes",
                  "coupling_energy_residual_J", "transmitted_energy_J", "torque_chatter_max",
                  "energy_residual_max_ratio")


def monitor_line(info: Mapping) -> str:
    """One line for a console report of a monitored run."""
    if info.get("coupling_stable") is None:
        return "coupling monitor: off"
    figs = (f"peak torque chatter {info['torque_chatter_max'] * 100:.2f} % of {info['monitor_torque_scale_Nm']:g} "
            f"N.m, energy residual {info['coupling_energy_residual_J']:.1f} J of "
            f"{info['transmitted_energy_J']:.0f} J transmitted")
    if info["coupling_stable"]:
        return f"coupling monitor: stable ({figs})"
    n = len(info["instability_episodes"])
    return f"WARNING: {info['instability']['message']} [{n} episode{'s' if n > 1 else ''}; {figs}]"


class _MonitorProbe:
    """The CouplingMonitor around every communication step of the master (fmu.master.run's probe)."""

    def __init__(self, mon: CouplingMonitor, drive, plant, scheme: str, step: float, on_instability: str):
        self.mon, self.drive, self.plant = mon, drive, plant
        self.scheme, self.gs, self.on_instability = scheme, scheme == "gauss-seidel", on_instability
        self.tk = time_grid(step)

    def start(self):
        self.iw, self.ia = self.plant.index("motor.speed"), self.plant.index("motor.angle")

    def before(self):
        y = self.plant.out
        self.w0, self.th0, self.tau0 = y[self.iw], y[self.ia], self.drive.out[0]

    def after(self, k: int) -> bool:
        d = self.drive.out
        ep = self.mon.update(self.tk(k + 1), d[0] if self.gs else self.tau0, d[0], d[1], self.w0, self.th0,
                             self.plant.out[self.ia])
        return ep is not None and _on_detection(self.mon, ep, self.scheme, self.on_instability)


# ------------------------------------------------------------------------------------------------
# fmpy master
# ------------------------------------------------------------------------------------------------
def cosimulate(plant_fmu, drive_fmu, *, step: float = 1e-3, t_end: Optional[float] = None,
               plant_values: Optional[Mapping[str, float]] = None,
               drive_values: Optional[Mapping[str, float]] = None, scheme: str = "gauss-seidel",
               record: Optional[Sequence[str]] = None, record_every: int = 1,
               progress: Optional[Callable[[float], None]] = None, progress_every: float = 0.25,
               timing: bool = False, echo_log: bool = False, ns_step_differences: bool = False,
               monitor: bool = True, on_instability: str = "warn", early_return: Optional[bool] = None) -> TimeSeries:
    """Co-simulate the plant and drive FMUs with fmpy `FMU2Slave`s (`FMU3Slave`s for FMI 3.0 FMUs; see the
    module docstring).

    step          communication step (s); any value > 0
    t_end         end time (default: the drive's last move + 1 s)
    plant_values, drive_values   start values of parameters ({"car.load": 1000.0, "pretorque[1]": ...})
    scheme        "gauss-seidel" (drive, then plant with the new torque) or "jacobi" (libcosim's order)
    record        plant outputs to record (default: all plant outputs); the drive's motor.torque,
                  brake.command and DRIVE_RECORD are always recorded
    record_every  record every n-th communication point
    progress      called with the simulated time every `progress_every` s of simulated time
    timing        measure every plant and drive doStep (info["plant_doStep_ns"], ...)
    ns_step_differences   pass communicationStepSize = t_(k+1) - t_k of the nanosecond time grid (it
                  differs from `step` by one ulp on most steps) instead of `step`: what libcosim does;
                  only for bit-for-bit comparisons with it (tests/fmu/test_cosim.py)
    monitor       run the CouplingMonitor on the exchanged torque/speed/angle (info["coupling_stable"],
                  info["instability_detected_at"], info["instability"], ...); the torque scale is the
                  drive's torque.max
    on_instability  "warn": log a warning and continue (the result is flagged); "stop": also end the
                  run at the detection (result truncated there); "raise": raise CosimInstability
    early_return  FMI 3.0 FMUs: instantiate them with earlyReturnAllowed and eventModeUsed, so that a step
                  ends at the plant's events (brake engagement, slack, slip) and the drive's brake command
                  switches, and the other FMU is stepped to that time (fmu.master, "Early return";
                  info["events"]: the times). Default: on for FMI 3.0 FMUs; FMI 2.0 FMUs have no early
                  return (True is then an error)

    The master is fmu.master.run over CONNECTIONS: per step exactly one setReal, doStep and getReal call
    per FMU through fmpy's ctypes functions with preallocated value-reference and value arrays; the
    plant's getReal writes motor.speed/angle straight into the buffer the drive's setReal reads, and vice
    versa.
    """
    from ..components.drive import trip_end_time
    from .runner import SlaveHandle

    if not (step > 0.0 and math.isfinite(step)):
        raise ValueError(f"communication step must be a finite number > 0, got {step!r}")
    if scheme not in SCHEMES:
        raise ValueError(f"scheme must be 'gauss-seidel' or 'jacobi', got {scheme!r}")
    if on_instability not in ON_INSTABILITY:
        raise ValueError(f"on_instability must be one of {ON_INSTABILITY}, got {on_instability!r}")
    if t_end is None:
        t_end = trip_end_time(drive_values)
    n = int(math.floor(t_end / step + 1e-9))
    if n < 1:
        raise ValueError(f"t_end = {t_end} s is shorter than one step ({step} s)")
    handles = []
    t_wall0 = time.perf_counter()
    try:
        plant, drive = _open_pair(SlaveHandle, plant_fmu, drive_fmu, handles, t_end, plant_values,
                                  drive_values, echo_log, early_return)
        plant_outputs = [v.name for v in plant.md.modelVariables if v.causality == "output" and not v.dimensions]
        rec = [r for r in (record if record is not None else plant_outputs) if r not in PLANT_EXCHANGE]
        missing = [r for r in rec if r not in plant.variables]
        if missing:
            raise ValueError(f"plant FMU has no variables {missing}")
        drive_rec = [r for r in DRIVE_RECORD if r in drive.variables and drive.variables[r].type in ("Real", "Float64")]
        recorded = {"plant": list(PLANT_EXCHANGE) + rec, "drive": list(DRIVE_EXCHANGE) + drive_rec}
        P, D = FmuUnit("plant", plant), FmuUnit("drive", drive)
        probe = None
        if monitor:
            scale = drive.get("torque.max") if "torque.max" in drive.variables else None
            probe = _MonitorProbe(CouplingMonitor(step, scale), D, P, scheme, step, on_instability)
        run = master.run([D, P], CONNECTIONS, n=n, step=step, scheme=scheme, record=recorded,
                         record_every=record_every, probe=probe, progress=progress, progress_every=progress_every,
                         timing=timing, ns_step_differences=ns_step_differences)
        warnings = [str(m) for h in handles for m in h.messages if m.status >= 1]
    finally:
        for h in reversed(handles):
            try:
                h.close()
            except Exception:  # pragma: no cover - teardown must not hide the real error
                pass
    info = {"master": "fmpy", "scheme": scheme, "step_s": step, "plant_outputs": plant_outputs,
            **_run_info(run, step, probe), "total_wall_s": time.perf_counter() - t_wall0,
            "first_step_wall_s": run.t_first,
            "rtf_after_first_step": ((run.n - 1) * step / (run.loop_wall - run.t_first)
                                     if run.n > 1 and run.loop_wall > run.t_first else math.inf),
            "fmu_warnings": warnings}
    if run.events is not None:
        info["events"] = [te for te, _ in run.events]
    if run.step_ns is not None:
        info["plant_doStep_ns"] = run.step_ns["plant"]["step"]
        info["drive_doStep_ns"] = run.step_ns["drive"]["step"]
    res = run.series(recorded, info)
    if run.failure is not None:
        run.failure.result, run.failure.time = res, run.n * step
        raise run.failure
    return res


def _run_info(run: master.MasterRun, step: float, probe: Optional[_MonitorProbe]) -> dict:
    """Steps, end time, loop wall, real-time factor and the coupling monitor's report of a run."""
    info = {"t_end_s": run.n * step, "steps": run.n, "loop_wall_s": run.loop_wall,
            "rtf": (run.n * step) / run.loop_wall if run.loop_wall > 0 else math.inf,
            "stopped_by_monitor": run.stop}
    if probe is not None:
        info.update(probe.mon.report(probe.scheme))
    return info


def _open_pair(SlaveHandle, plant_fmu, drive_fmu, handles: list, t_end, plant_values, drive_values, echo_log,
               early_return: Optional[bool] = None):
    """Open, set up and initialize both FMUs (appended to `handles` as they open, so that the caller
    closes whatever was opened); an initialization error raises CosimError with the FMU's log.
    early_return: see cosimulate."""
    from fmpy import read_model_description

    fmi3 = {k: read_model_description(str(f)).fmiVersion.startswith("3")
            for k, f in (("plant", plant_fmu), ("drive", drive_fmu))}
    if early_return and not all(fmi3.values()):
        raise ValueError(f"early_return: {Path(plant_fmu if not fmi3['plant'] else drive_fmu).name} is an FMI 2.0 "
                         f"FMU (early return is FMI 3.0; build it with reeve-fmu build --fmi 3)")
    early = {k: v if early_return is None else bool(early_return) for k, v in fmi3.items()}
    plant = SlaveHandle.open(plant_fmu, "plant", echo=echo_log, early_return=early["plant"])
    handles.append(plant)
    drive = SlaveHandle.open(drive_fmu, "drive", echo=echo_log, early_return=early["drive"])
    handles.append(drive)
    plant.setup(0.0, t_end, start_values=dict(plant_values or {}))
    drive.setup(0.0, t_end, start_values=dict(drive_values or {}))
    for h in handles:
        errs = h.errors()
        if errs:
            raise CosimError(f"{h.instance_name}: initialization failed\n{h.log_text()}")
    return plant, drive


# ------------------------------------------------------------------------------------------------
# monolithic reference (no FMI)
# ------------------------------------------------------------------------------------------------
def monolithic(*, step: float = 1e-4, t_end: Optional[float] = None, record_step: float = 1e-3,
               scene=None, plant_fmu=None, plant_values: Optional[Mapping[str, float]] = None,
               drive_values: Optional[Mapping[str, float]] = None, scheme: str = "gauss-seidel",
               progress: Optional[Callable[[float], None]] = None, monitor: bool = True,
               on_instability: str = "warn") -> TimeSeries:
    """The same Plant and ElectricDrive as the FMUs, coupled in this process every `step` seconds
    (Gauss-Seidel: the drive steps first with the measurement at t, the plant then holds the drive's
    torque over [t, t + step]); samples every `record_step` (a multiple of `step`).

    With step = the co-simulation's communication step and scheme equal, this is exactly what the FMU
    co-simulation computes (tests compare them bit for bit); with a much finer step it is the
    reference of the co-simulation error (docs/cosim.md). The plant comes from `scene` (default: the
    shipped elevator_2to1 scene) or, if given, from the scene the plant FMU `plant_fmu` carries.
    `monitor`/`on_instability`: the CouplingMonitor at the coupling step, as in `cosimulate`.
    The master is fmu.master.run over CONNECTIONS (plus car.position to the drive's shaft information
    system when it has one), with the models as PlantUnit and DriveUnit."""
    from ..components.drive import make_drive
    from ..components.plant import make_plant

    if scheme not in SCHEMES:
        raise ValueError(f"scheme must be 'gauss-seidel' or 'jacobi', got {scheme!r}")
    if on_instability not in ON_INSTABILITY:
        raise ValueError(f"on_instability must be one of {ON_INSTABILITY}, got {on_instability!r}")
    payload = None
    if plant_fmu is not None:
        scene, payload = plant_fmu_model(plant_fmu)
    scene = scene if scene is not None else default_scene_path()
    plant = make_plant(scene, payload, plant_values)
    drive = make_drive(drive_values)
    if t_end is None:
        t_end = drive.t_end + 1.0
    n = int(math.floor(t_end / step + 1e-9))
    m = int(round(record_step / step))
    if m < 1 or abs(m * step - record_step) > 1e-9 * record_step:
        raise ValueError(f"record_step {record_step} must be a multiple of step {step}")
    P, D = master.PlantUnit("plant", plant), master.DriveUnit("drive", drive)
    # the shaft information system reads the car position (in process only)
    sis = (("plant.car.position", "drive.car.position"),) if drive.params.sis else ()
    recorded = {"plant": [s for s in plant.output_names if s != "motor.torque"],
                "drive": list(DRIVE_EXCHANGE + DRIVE_RECORD)}
    probe = _MonitorProbe(CouplingMonitor(step, drive.params.T_max), D, P, scheme, step, on_instability) \
        if monitor else None
    run = master.run([D, P], CONNECTIONS + sis, n=n, step=step, scheme=scheme, record=recorded, record_every=m,
                     probe=probe, progress=progress)
    run.drop_partial()      # the reference samples whole record steps only
    return run.series(recorded, {"master": "monolithic", "scheme": scheme, "step_s": step,
                                 **_run_info(run, step, probe)})


# ------------------------------------------------------------------------------------------------
# SSP
# ------------------------------------------------------------------------------------------------
def ssp_parameters(ssp_dir) -> dict:
    """{component name: {parameter: value}} from the inline ParameterBindings of an SSP directory's
    SystemStructure.ssd (Real, Integer and Boolean values), and the FMU source of each component
    under the key "__source__"."""
    from xml.etree import ElementTree as ET

    ns = {"ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
          "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues"}
    root = ET.parse(Path(ssp_dir) / "SystemStructure.ssd").getroot()
    out = {}
    for comp in root.iter(f"{{{ns['ssd']}}}Component"):
        vals = {"__source__": comp.get("source")}
        for p in comp.iter(f"{{{ns['ssv']}}}Parameter"):
            for kind, conv in (("Real", float), ("Integer", int), ("Boolean", lambda s: s == "true")):
                e = p.find(f"ssv:{kind}", ns)
                if e is not None:
                    vals[p.get("name")] = conv(e.get("value"))
        out[comp.get("name")] = vals
    return out
