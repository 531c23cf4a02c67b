"""`reeve-fmu hil` runs: the configuration, the bench with its controller (a thread on the virtual bus,
a process on udp_multicast, or an external CANopen master) and the in-process reference runs.

The summary, verdicts and written results of a run are in reeve_fmu.hil.review; the command lines in
reeve_fmu.hil.cli.
"""
from __future__ import annotations

import contextlib
import json
import math
import os
import random
import shutil
import subprocess
import sys
import tempfile
import threading
import time
import uuid
from dataclasses import dataclass, field, replace
from pathlib import Path


import numpy as np

from ..fmu.master import DriveUnit, PlantUnit, run
from .buses import DEFAULT_UDP_PORT, MULTICAST_GROUP, MULTICAST_MODES, bench_route, ensure_multicast, make_bus


# ---------------------------------------------------------------------------------------------------
# configuration
# ---------------------------------------------------------------------------------------------------
@dataclass
class HilConfig:
    bus: str = "virtual"                       # virtual | udp_multicast
    controller: str = "builtin"                # builtin | external
    realtime: bool = False
    inject: list = field(default_factory=list)
    t_end: float | None = None                 # default: the drive's trip end + 1 s (like the demo)
    dt: float = 1e-3
    plant: str = "fmu"                         # fmu | in-process
    fmu_path: str | None = None                # default: fmus/ReevingPlant.fmu (built when missing/stale)
    drive_values: dict | None = None           # drive parameters (components.drive.DRIVE_PARAMETERS names); None: the demo's
    plant_values: dict | None = None           # plant FMU parameters (car.load, ...); None: the demo's
    out: str | None = "results/hil"
    lockstep_timeout: float = 0.5
    start_timeout: float = 300.0              # a cold numba compile of plant + drive can take minutes
    channel: str | None = None
    port: int | None = None
    multicast: str = "host"                    # udp_multicast: host | route | lan (buses.MULTICAST_MODES)
    compare: bool = True                       # builtin, no faults: compare with the in-process references
    stop_when_safe: bool = False
    record: bool = True
    rt_priority: int | None = None             # SCHED_FIFO priority of bench + controller; None: 50 in real time, off in lock-step


_DEMO_SCENARIO: tuple | None = None


def demo_scenario() -> tuple[dict, dict]:
    """(plant_values, drive_values) of `reeve-fmu demo` (reeve_fmu/demo.py): the shipped 2:1 scene at its
    rated load, landings 0 m and 39 m, one round trip, Level-1 drive sized from the scene
    (studies.trip.trip_case: torque and power limits, inertia, speed-loop gains), pre-torque = the plant's
    holding torque at each landing. The built-in controller runs this drive; the bench runs this plant."""
    global _DEMO_SCENARIO
    if _DEMO_SCENARIO is None:
        from ..studies.trip import trip_case

        case = trip_case(None)
        _DEMO_SCENARIO = (dict(case.plant_values), dict(case.drive_values))
    return dict(_DEMO_SCENARIO[0]), dict(_DEMO_SCENARIO[1])


def _drive_model(values):
    from .controller import make_electric_drive

    return make_electric_drive(values)


def default_t_end(drive_values=None) -> float:
    """The demo's end time: the drive's last move + 1 s."""
    return _drive_model(drive_values).t_end + 1.0


def _make_plant(cfg: HilConfig, log):
    from .plants import FmuPlant, InProcessPlant, default_plant_fmu, make_default_plant

    if cfg.plant == "in-process":
        return InProcessPlant(make_default_plant(params=cfg.plant_values))
    path = Path(cfg.fmu_path) if cfg.fmu_path else default_plant_fmu(log=log)
    return FmuPlant(path, start_values=cfg.plant_values)


# ---------------------------------------------------------------------------------------------------
# reference runs (in-process, no bus)
# ---------------------------------------------------------------------------------------------------
def reference_run(n_steps: int, dt: float = 1e-3, *, drive_values=None, plant_values=None,
                  scheme: str = "hil", names=("car.position", "car.velocity", "motor.speed")):
    """Plant + ElectricDrive in this process, no FMI, no bus: fmu.master.run over the elevator's
    connections (fmu.cosim.CONNECTIONS), communication points k * dt.

    scheme "hil":  the bench's semantics: the torque held over [t_k, t_k+1) was computed by the controller
                   from the sample at t_k-1 (Jacobi coupling) and went through the CAN encoding (angle and
                   speed in 2^20 increments per revolution, torque in 0.55 N m);
    scheme "gauss-seidel": the demo's coupling (drive first with the sample at t_k, its torque held over
                   [t_k, t_k+1)), full float precision.
    Returns a TimeSeries of `names` sampled at every t_k (k = 0..n_steps)."""
    from ..fmu.cosim import CONNECTIONS
    from .controller import max_torque_permille
    from .plants import make_default_plant
    from .protocol import NM_PER_PERMILLE

    plant = make_default_plant(params=plant_values)
    drive = _drive_model(drive_values)
    if scheme == "hil":
        tmax = max_torque_permille(drive) * NM_PER_PERMILLE      # the controller's clamp (0x6072)
        units = [_CanDriveUnit("drive", drive, tmax), PlantUnit("plant", plant)]
    else:
        units = [DriveUnit("drive", drive), PlantUnit("plant", plant)]
    recorded = {"plant": list(names)}
    r = run(units, CONNECTIONS, n=n_steps, step=dt, grid="multiply", record=recorded,
            scheme="jacobi" if scheme == "hil" else "gauss-seidel")
    return r.series(recorded)


class _CanDriveUnit(DriveUnit):
    """The drive as the bench sees it over CAN: speed and angle in 2^20 increments per revolution, the
    torque command clamped to 0x6072 and in 0.55 N m, the brake command 0 or 1."""

    def __init__(self, name, drive, tmax):
        from .protocol import NM_PER_PERMILLE, RAD_PER_INC

        super().__init__(name, drive)
        self.tmax, self.nm, self.rad = tmax, NM_PER_PERMILLE, RAD_PER_INC

    def advance(self, t, h, u):
        rad, nm = self.rad, self.nm
        tq, br = self.drive.step(t, h, round(u[0] / rad) * rad, round(u[1] / rad) * rad)
        tq = min(max(tq, -self.tmax), self.tmax)
        return round(tq / nm) * nm, (1.0 if br > 0.5 else 0.0)


# ---------------------------------------------------------------------------------------------------
# controller runners
# ---------------------------------------------------------------------------------------------------
class _ThreadController:
    def __init__(self, bus_factory, ccfg):
        from .controller import BuiltinController

        self.bus = bus_factory()
        self.ctl = BuiltinController(self.bus, ccfg)
        self.result = None
        self.thread = threading.Thread(target=self._run, name="hil-controller", daemon=True)

    def _run(self):
        self.result = self.ctl.run()

    def start(self):
        self.thread.start()

    def dead(self):
        if self.thread.is_alive():
            return None
        return self.result.stopped if self.result is not None else "controller thread ended"

    def join(self, timeout):
        self.thread.join(timeout)
        alive = self.thread.is_alive()
        try:
            self.bus.shutdown()
        except Exception:
            pass
        st = self.result.as_dict() if self.result is not None else {"stopped": "controller thread did not finish"}
        if alive:
            st["stopped"] = "controller thread still running after the bench stopped"
        return st


class _ProcessController:
    def __init__(self, channel, port, ccfg, workdir: Path, multicast: str = "host"):
        self.stats_path = workdir / "controller_stats.json"
        self.log_path = workdir / "controller.log"
        args = [sys.executable, "-m", "reeve_fmu.hil", "controller", "--bus", "udp_multicast",
                "--multicast", multicast, "--channel", channel, "--port", str(port), "--n-steps", str(ccfg.n_steps), "--dt", repr(ccfg.dt),
                "--sync-timeout", repr(ccfg.sync_timeout), "--start-timeout", repr(ccfg.start_timeout),
                "--stats", str(self.stats_path)]
        if ccfg.dies_at is not None:
            args += ["--dies-at", repr(ccfg.dies_at)]
        if ccfg.rt_priority:
            args += ["--rt-priority", str(int(ccfg.rt_priority))]
        if ccfg.drive_values:
            args += ["--drive-values", json.dumps(ccfg.drive_values)]
        env = dict(os.environ)
        root = str(Path(__file__).resolve().parents[2])
        env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
        self._log = open(self.log_path, "w", encoding="utf-8")
        self.proc = subprocess.Popen(args, env=env, stdout=self._log, stderr=subprocess.STDOUT,
                                     start_new_session=True)

    def start(self):
        pass

    def dead(self):
        rc = self.proc.poll()
        if rc is None:
            return None
        return f"controller process exited with code {rc} (see controller.log)"

    def join(self, timeout):
        try:
            rc = self.proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            rc = self.proc.wait(timeout=10)
        self._log.close()
        try:
            st = json.loads(self.stats_path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            st = {"stopped": f"controller process wrote no statistics (exit code {rc}); see {self.log_path.name}"}
        st["exit_code"] = rc
        st["pid"] = self.proc.pid
        return st


# ---------------------------------------------------------------------------------------------------
# the run
# ---------------------------------------------------------------------------------------------------
def run_hil(cfg: HilConfig, log=print) -> dict:
    """Run the bench with the configured controller; write results (if cfg.out) and return the summary."""
    from .bridge import FaultSpec
    from .review import add_trip_figures, add_verdicts, json_default, summarize, write_results

    log = log or (lambda *a, **k: None)
    _check_config(cfg)
    faults = FaultSpec.parse(cfg.inject)
    cfg, n = _with_defaults(cfg)
    route = cfg.bus == "udp_multicast" and cfg.multicast == "route"
    with bench_route(cfg.channel or MULTICAST_GROUP, log) if route else contextlib.nullcontext():
        res, plant, ctl_stats = _run_bench(cfg, faults, n, log)
    st = res.stats
    cols = res.record.columns if res.record is not None else {}
    time_ = res.record.time if res.record is not None else None
    summary = summarize(cfg, faults, res, plant, cols, ctl_stats)
    if cols:
        add_trip_figures(summary, cfg, time_, cols)
        add_verdicts(summary, cfg, plant, faults.any, time_, cols)   # trip, coupling and bench checks
    if cfg.compare and cfg.controller == "builtin" and not faults.any and cols and st.steps > 0:
        _add_reference_comparison(summary, cfg, cols, st.steps)
    if cfg.out:
        write_results(Path(cfg.out), cfg, summary, time_, cols, st)
    return json.loads(json.dumps(summary, default=json_default))


def _add_reference_comparison(summary: dict, cfg: HilConfig, cols: dict, m: int):
    """The record against in-process runs of the same plant and drive: with the bench's one-cycle
    delay and CAN quantization ("reference"), and with the demo's Gauss-Seidel coupling."""
    names = ("car.position", "car.velocity", "motor.speed")
    for key, scheme in (("reference", "hil"), ("vs_demo_scheme", "gauss-seidel")):
        t0 = time.perf_counter()
        ref = reference_run(m, cfg.dt, drive_values=cfg.drive_values, plant_values=cfg.plant_values,
                            scheme=scheme, names=names)
        d = {f"max_abs_diff_{n.replace('.', '_')}": float(np.max(np.abs(cols[n][:m + 1] - ref[n])))
             for n in names}
        d["scheme"] = ("in-process Plant + ElectricDrive, same step, one-cycle transport delay (Jacobi), same "
                       "CAN quantization" if scheme == "hil" else
                       "in-process Plant + ElectricDrive, same step, Gauss-Seidel (the demo's coupling), "
                       "no CAN quantization")
        d["wall_s"] = time.perf_counter() - t0
        summary[key] = d


def _check_config(cfg: HilConfig):
    """Bus, controller and step of the configuration; raises ValueError naming the option."""
    if cfg.bus not in ("virtual", "udp_multicast"):
        raise ValueError(f"--bus must be virtual or udp_multicast, got {cfg.bus!r}")
    if cfg.multicast not in MULTICAST_MODES:
        raise ValueError(f"--multicast must be one of {', '.join(MULTICAST_MODES)}, got {cfg.multicast!r}")
    if cfg.controller not in ("builtin", "external"):
        raise ValueError(f"--controller must be builtin or external, got {cfg.controller!r}")
    if not (cfg.dt > 0 and math.isfinite(cfg.dt)):
        raise ValueError(f"step must be > 0, got {cfg.dt!r}")


def _with_defaults(cfg: HilConfig):
    """The demo's scenario where the configuration gives none, and the number of SYNC cycles."""
    if cfg.plant_values is None or cfg.drive_values is None:
        pv, dv = demo_scenario()
        cfg = replace(cfg, plant_values=pv if cfg.plant_values is None else cfg.plant_values,
                      drive_values=dv if cfg.drive_values is None else cfg.drive_values)
    t_end = cfg.t_end if cfg.t_end is not None else default_t_end(cfg.drive_values)
    if not (t_end > 0 and math.isfinite(t_end)):
        raise ValueError(f"--t-end must be > 0, got {t_end!r}")
    n = int(math.floor(t_end / cfg.dt + 1e-9))
    if n < 1:
        raise ValueError(f"--t-end {t_end} s is shorter than one SYNC period")
    return cfg, n


def _run_bench(cfg: HilConfig, faults, n: int, log):
    """Bus, plant, bridge and controller (a thread on the virtual bus, a process on udp_multicast, or
    an external CANopen master): run n SYNC cycles, then shut everything down. Returns the bridge's
    result, the (closed) plant and the controller's statistics."""
    from .bridge import Bridge, BridgeConfig, HilError, Injector, effective_rt_priority
    from .controller import ControllerConfig
    from .protocol import EDS_PATH, DBC_PATH

    if cfg.bus == "udp_multicast":
        ok, why = ensure_multicast(cfg.multicast)
        if not ok:
            raise HilError(f"--bus udp_multicast is not usable here: {why}")
    channel = cfg.channel or (f"reeve_hil_{uuid.uuid4().hex[:8]}" if cfg.bus == "virtual" else MULTICAST_GROUP)
    port = cfg.port or (None if cfg.bus == "virtual" else
                        (DEFAULT_UDP_PORT if cfg.controller == "external" else random.randint(43200, 43999)))
    plant = _make_plant(cfg, log)
    bus = make_bus(cfg.bus, channel, port, multicast=cfg.multicast)
    workdir = Path(tempfile.mkdtemp(prefix="reeve_hil_"))
    ctl = None
    try:
        bcfg = BridgeConfig(dt=cfg.dt, realtime=cfg.realtime, lockstep_timeout=cfg.lockstep_timeout,
                            start_timeout=cfg.start_timeout, stop_when_safe=cfg.stop_when_safe, record=cfg.record,
                            rt_priority=cfg.rt_priority)
        inj = Injector(faults, cfg.dt, lockstep=not cfg.realtime) if faults.any else None
        bridge = Bridge(bus, plant, bcfg, inj)
        bridge.warm_up()
        if cfg.controller == "builtin":
            ccfg = ControllerConfig(dt=cfg.dt, n_steps=n, drive_values=cfg.drive_values,
                                    dies_at=faults.controller_dies_at, start_timeout=cfg.start_timeout,
                                    sync_timeout=max(5.0, 4 * cfg.lockstep_timeout),
                                    rt_priority=effective_rt_priority(cfg.rt_priority, cfg.realtime))
            if cfg.bus == "virtual":
                ctl = _ThreadController(lambda: make_bus("virtual", channel), ccfg)
            else:
                ctl = _ProcessController(channel, port, ccfg, workdir, cfg.multicast)
            ctl.start()
        else:
            log(f"waiting up to {cfg.start_timeout:g} s for a CANopen master on {cfg.bus} "
                f"{channel}{'' if port is None else f':{port}'}: drive node 1 ({EDS_PATH.name}, {DBC_PATH.name})")
        res = bridge.run(n, alive=ctl.dead if ctl is not None else None)
    finally:
        try:
            bus.shutdown()
        except Exception:
            pass
        plant.close()
        ctl_stats = ctl.join(timeout=30.0) if ctl is not None else None
        if ctl is not None and isinstance(ctl, _ProcessController) and cfg.out:
            out_dir = Path(cfg.out)
            out_dir.mkdir(parents=True, exist_ok=True)
            shutil.copy(ctl.log_path, out_dir / "controller.log")
        shutil.rmtree(workdir, ignore_errors=True)
    return res, plant, ctl_stats
