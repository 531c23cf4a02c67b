"""`reeve-fmu hil`: the motor controller in the loop over CAN (CiA 402), docs/hil.md.

The bench (reeve_fmu.hil.bridge) is a simulated CiA 402 drive in front of the plant FMU; the
controller sits on the other side of a python-can bus:

    --bus virtual        controller in a thread of this process (python-can `virtual` is in-process only)
    --bus udp_multicast  controller in a separate process (IPv4 multicast 239.74.163.2 on loopback)
    --controller builtin the demo's ElectricDrive as a CANopen master (reeve_fmu.hil.controller)
    --controller external  wait for another CANopen master (e.g. canopen BaseNode402, a real controller)
    --realtime           pace SYNC to the wall clock (default: lock-step, deterministic, faster than real time)
    --inject loss=P | delay=MS | controller-dies-at=T | corrupt=P | seed=N

Writes DIR/results.csv (plant outputs + hil.* columns per SYNC) and DIR/summary.json. With the built-in
controller and no injected faults the summary compares the run with an in-process Plant + ElectricDrive
run of the same step, transport delay and CAN quantization (`reference`), and with the demo's
Gauss-Seidel coupling without CAN (`vs_demo_scheme`).

`python -m reeve_fmu.hil controller ...` is the controller process of --bus udp_multicast;
`python -m reeve_fmu.hil bench ...` runs the bench on any python-can interface (socketcan for a real
controller, docs/hil.md).
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

from .buses import DEFAULT_UDP_PORT, MULTICAST_GROUP, MULTICAST_MODES, make_bus  # noqa: E402


# ---------------------------------------------------------------------------------------------------
# buses
# ---------------------------------------------------------------------------------------------------
def multicast_probe(port: int | None = None, timeout: float = 1.0, multicast: str = "host") -> tuple[bool, str]:
    """Can two udp_multicast buses on this host exchange a frame? (ok, reason)."""
    import can

    port = port or random.randint(44000, 44999)
    a = b = None
    try:
        a = make_bus("udp_multicast", port=port, multicast=multicast)
        b = make_bus("udp_multicast", port=port, multicast=multicast)
        a.send(can.Message(arbitration_id=0x7FF, data=b"probe", is_extended_id=False))
        deadline = time.perf_counter() + timeout
        while time.perf_counter() < deadline:
            m = b.recv(max(0.0, deadline - time.perf_counter()))
            if m is not None and m.arbitration_id == 0x7FF:
                return True, "ok"
        return False, f"udp_multicast: a frame sent to {MULTICAST_GROUP} was not received within {timeout:g} s"
    except Exception as exc:  # CanInitializationError, OSError
        return False, f"udp_multicast: {type(exc).__name__}: {exc}"
    finally:
        for bus in (a, b):
            if bus is not None:
                try:
                    bus.shutdown()
                except Exception:
                    pass


def ensure_multicast(multicast: str = "host") -> tuple[bool, str]:
    """Is udp_multicast usable on this host? Probes with two buses; changes nothing (the host-only buses
    keep the frames on the loopback interface by their socket options). Returns (ok, reason)."""
    return multicast_probe(multicast=multicast)


def _ip(*args) -> subprocess.CompletedProcess:
    return subprocess.run([shutil.which("ip") or "ip", *args], capture_output=True, text=True, encoding="utf-8",
                          errors="replace", timeout=10)


class _Signals:
    """SIGTERM and SIGHUP raise SystemExit while the bench runs, so that `finally` blocks undo what was set up
    (Ctrl-C already raises KeyboardInterrupt); the previous handlers come back at exit."""

    SIGNALS = ("SIGTERM", "SIGHUP")

    def __enter__(self):
        import signal

        self.old = {}
        if threading.current_thread() is threading.main_thread():
            for name in self.SIGNALS:
                sig = getattr(signal, name, None)
                if sig is not None:
                    self.old[sig] = signal.signal(sig, self._raise)
        return self

    @staticmethod
    def _raise(signum, frame):
        raise SystemExit(128 + signum)

    def __exit__(self, *exc):
        import signal

        for sig, handler in self.old.items():
            signal.signal(sig, handler)
        return False


@contextlib.contextmanager
def bench_route(group: str = MULTICAST_GROUP, log=print):
    """--multicast route: while the bench runs, route the bench's own group (a /32, never a range) to lo,
    with lo's multicast flag on if it was off; said on the console and undone at exit, also after a fault,
    Ctrl-C, SIGTERM or SIGHUP. Root only; only what was not already so is changed and undone."""
    if not (hasattr(os, "geteuid") and os.geteuid() == 0) or shutil.which("ip") is None:
        raise ValueError("--multicast route changes the routing table: it needs root and the `ip` command "
                         "(the default --multicast host needs neither)")
    undo = []
    with _Signals():
        try:
            if "MULTICAST" not in _ip("link", "show", "lo").stdout.split(">")[0]:
                r = _ip("link", "set", "lo", "multicast", "on")
                if r.returncode != 0:
                    raise OSError(f"ip link set lo multicast on: {r.stderr.strip()}")
                undo.append(("link", "set", "lo", "multicast", "off"))
                log("network: ip link set lo multicast on (undone at exit)")
            if "dev lo" not in _ip("route", "show", "exact", f"{group}/32").stdout:
                r = _ip("route", "add", f"{group}/32", "dev", "lo")
                if r.returncode != 0:
                    raise OSError(f"ip route add {group}/32 dev lo: {r.stderr.strip()}")
                undo.append(("route", "del", f"{group}/32", "dev", "lo"))
                log(f"network: ip route add {group}/32 dev lo (undone at exit)")
            yield
        finally:
            for args in reversed(undo):
                r = _ip(*args)
                log(f"network: ip {' '.join(args)}" + ("" if r.returncode == 0 else f" FAILED: {r.stderr.strip()}"))


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
                  scheme: str = "hil", names=("car.position", "car.velocity", "motor.speed")) -> dict:
    """Plant + ElectricDrive in this process, no FMI, no bus.

    scheme "hil":  the bench's semantics: the torque held over [t_k, t_k+1) was computed by the controller
                   from the sample at t_k-1 (Jacobi coupling) and went through the CAN encoding (angle and
                   speed in 2^20 increments per revolution, torque in 0.55 N m);
    scheme "gauss-seidel": the demo's coupling (drive first with the sample at t_k, its torque held over
                   [t_k, t_k+1)), full float precision.
    Returns {"time": ..., name: ...} sampled at every t_k (k = 0..n_steps)."""
    from .controller import max_torque_permille
    from .plants import make_default_plant
    from .protocol import NM_PER_PERMILLE, RAD_PER_INC

    plant = make_default_plant(params=plant_values)
    drive = _drive_model(drive_values)
    tmax = max_torque_permille(drive) * NM_PER_PERMILLE      # the controller's clamp (0x6072)
    on = list(plant.output_names)
    iw, ia = on.index("motor.speed"), on.index("motor.angle")
    idx = [on.index(n) for n in names]
    out = np.empty((n_steps + 1, len(names)))
    od = plant.outputs()
    y = np.array([od[n] for n in on])
    out[0] = y[idx]
    tau, brake = 0.0, 0.0
    jacobi = scheme == "hil"
    for k in range(n_steps):
        w, th = y[iw], y[ia]
        if jacobi:
            w = round(w / RAD_PER_INC) * RAD_PER_INC
            th = round(th / RAD_PER_INC) * RAD_PER_INC
            y = plant.step(dt, tau, brake)
            tq, br = drive.step(k * dt, dt, w, th)
            tq = min(max(tq, -tmax), tmax)
            tau, brake = round(tq / NM_PER_PERMILLE) * NM_PER_PERMILLE, (1.0 if br > 0.5 else 0.0)
        else:
            tau, brake = drive.step(k * dt, dt, w, th)
            y = plant.step(dt, tau, brake)
        out[k + 1] = y[idx]
    res = {"time": np.arange(n_steps + 1) * dt}
    res.update({n: out[:, i] for i, n in enumerate(names)})
    return res


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
def _pct(a, q):
    return float(np.percentile(a, q)) if len(a) else None


def run_hil(cfg: HilConfig, log=print) -> dict:
    """Run the bench with the configured controller; write results (if cfg.out) and return the summary."""
    from .bridge import FaultSpec

    log = log or (lambda *a, **k: None)
    _check_config(cfg)
    faults = FaultSpec.parse(cfg.inject)
    cfg, n = _with_defaults(cfg)
    route = cfg.bus == "udp_multicast" and cfg.multicast == "route"
    with bench_route(cfg.channel or MULTICAST_GROUP, log) if route else contextlib.nullcontext():
        res, plant, ctl_stats = _run_bench(cfg, faults, n, log)
    st = res.stats
    cols = res.columns() if res.outputs is not None else {}
    summary = _summary(cfg, faults, res, plant, cols, ctl_stats)
    if cols:
        from .review import add_verdicts

        _add_trip_figures(summary, cfg, res.time, cols)
        add_verdicts(summary, cfg, plant, faults.any, res.time, cols)   # trip, coupling and bench checks
    if cfg.compare and cfg.controller == "builtin" and not faults.any and cols and st.steps > 0:
        _add_reference_comparison(summary, cfg, cols, st.steps)
    if cfg.out:
        _write_results(Path(cfg.out), cfg, summary, res.time, cols, st)
    return json.loads(json.dumps(summary, default=_json_default))


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


def _summary(cfg: HilConfig, faults, res, plant, cols: dict, ctl_stats) -> dict:
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


def _add_trip_figures(summary: dict, cfg: HilConfig, time_, cols: dict):
    """Car travel and speed, peak tension and torque of the record."""
    x = cols.get("car.position")
    v = cols.get("car.velocity")
    if x is not None:
        summary.update({"car_travel_max_m": float(np.max(x) - x[0]), "car_position_final_m": float(x[-1]),
                        "car_speed_max_m_s": float(np.max(np.abs(v))) if v is not None else None})
    if "traction.tension_in" in cols:
        summary["traction_tension_in_max_N"] = float(np.max(cols["traction.tension_in"]))
    summary["motor_torque_peak_Nm"] = float(np.max(np.abs(cols["hil.torque"])))


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


def _write_results(out: Path, cfg: HilConfig, summary: dict, time_, cols: dict, st):
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
    (out / "summary.json").write_text(json.dumps(summary, indent=2, default=_json_default) + "\n",
                                       encoding="utf-8")
    if cols:
        from .review import write_report

        write_report(out, cfg, summary, time_, cols)


def _json_default(o):
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    raise TypeError(f"not JSON serialisable: {o!r}")


# ---------------------------------------------------------------------------------------------------
# command lines
# ---------------------------------------------------------------------------------------------------
SUMMARY_KEYS = ("mode", "steps", "wall_s", "steps_per_s", "watchdog_trips", "brake_engaged_at", "frames_rejected",
                "deadline_misses", "lockstep_timeouts", "final_state", "car_position_final_m",
                "step_time_p50_us", "step_time_p99_us", "sync_jitter_p99_us")


def _hil_sets(items) -> dict:
    """--set for hil: the load, the plant FMU's parameters (rope.EA, ...) and drive parameters on top of
    the demo's scenario; other scene keys need a plant FMU built with them (reeve-fmu build --set)."""
    from ..components.plant import PLANT_PARAMETERS, holding_torques
    from ..studies.overrides import OverrideError, parse_sets, split

    sets = parse_sets(items)
    plant = {k: float(sets.pop(k)) for k in list(sets) if k in PLANT_PARAMETERS}
    scene_sets, drive_sets, load = split(sets)
    if scene_sets:
        raise OverrideError(f"--set {next(iter(scene_sets))}: hil runs the built plant FMU; its parameters are "
                            f"{', '.join(PLANT_PARAMETERS)} (other scene keys: reeve-fmu build --set)")
    pv, dv = demo_scenario()
    if load is not None:
        plant["car.load"] = load
    pv.update(plant)
    if "car.load" in plant:      # load weighing: the pre-torque follows the load
        from ..core.scene import load_scene
        from ..fmu import cosim
        from ..studies import trip as demo

        pre = holding_torques(load_scene(cosim.default_scene_path()), demo.LANDINGS, pv["car.load"],
                              params={k: v for k, v in pv.items() if k != "car.load"})
        dv.update({"pretorque[1]": pre[0], "pretorque[2]": pre[1]})
    dv.update(drive_sets)
    return {"plant_values": pv, "drive_values": dv}


def cli_hil(args) -> int:
    """reeve-fmu hil (arguments from reeve_fmu.cli)."""
    from .bridge import HilError

    cfg = HilConfig(bus=args.bus, controller=args.controller, realtime=args.realtime, inject=list(args.inject or []),
                    t_end=args.t_end, out=args.out, multicast=getattr(args, "multicast", "host"))
    if getattr(args, "set", None):
        cfg = replace(cfg, **_hil_sets(args.set))
    print(f"HIL: {'real time' if cfg.realtime else 'lock-step'} over {cfg.bus}, {cfg.controller} controller"
          + (f", faults {' '.join(cfg.inject)}" if cfg.inject else ""))
    try:
        summary = run_hil(cfg)
    except HilError as exc:
        print(f"reeve-fmu hil: error: {exc}", file=sys.stderr)
        return 3
    return _print_summary(summary, cfg)


def _print_summary(summary: dict, cfg) -> int:
    w = max(len(k) for k in SUMMARY_KEYS)
    for k in SUMMARY_KEYS:
        if k in summary:
            v = summary[k]
            print(f"  {k:{w}s}  {v:.6g}" if isinstance(v, float) else f"  {k:{w}s}  {v}")
    for key in ("reference", "vs_demo_scheme"):
        if key in summary:
            print(f"  {key:{w}s}  max |dx_car| = {summary[key]['max_abs_diff_car_position']:.3g} m")
    if summary.get("verdicts"):
        from ..studies.verdicts import print_verdicts

        tm = summary.get("trip_metrics")
        print_verdicts(summary["verdicts"], summary=tm if isinstance(tm, dict) else None)
    if summary.get("verdicts_note"):
        print(f"  {summary['verdicts_note']}")
    print(f"-> {cfg.out}/results.csv, summary.json" + (", report.md" if summary.get("verdicts") else ""))
    return 0 if summary.get("plant_error") is None else 2


def _controller_main(argv) -> int:
    import argparse

    from .controller import BuiltinController, ControllerConfig

    ap = argparse.ArgumentParser(prog="python -m reeve_fmu.hil controller")
    ap.add_argument("--bus", default="udp_multicast")
    ap.add_argument("--multicast", choices=MULTICAST_MODES, default="host")
    ap.add_argument("--channel", default=None)
    ap.add_argument("--port", type=int, default=None)
    ap.add_argument("--n-steps", type=int, required=True)
    ap.add_argument("--dt", type=float, default=1e-3)
    ap.add_argument("--dies-at", type=float, default=None)
    ap.add_argument("--sync-timeout", type=float, default=5.0)
    ap.add_argument("--start-timeout", type=float, default=60.0)
    ap.add_argument("--drive-values", default=None, help="JSON object of drive parameters")
    ap.add_argument("--stats", default=None, help="write the controller statistics (JSON) here")
    ap.add_argument("--rt-priority", type=int, default=0, help="SCHED_FIFO priority while cycling (0: off)")
    a = ap.parse_args(argv)
    ccfg = ControllerConfig(dt=a.dt, n_steps=a.n_steps, dies_at=a.dies_at, sync_timeout=a.sync_timeout,
                            start_timeout=a.start_timeout, rt_priority=a.rt_priority,
                            drive_values=json.loads(a.drive_values) if a.drive_values else None)
    bus = make_bus(a.bus, a.channel, a.port, multicast=a.multicast)
    try:
        st = BuiltinController(bus, ccfg).run()
    finally:
        bus.shutdown()
    d = st.as_dict()
    if a.stats:
        Path(a.stats).write_text(json.dumps(d), encoding="utf-8")
    print(json.dumps(d))
    return 0


def _bench_main(argv) -> int:
    """The bench on any python-can interface (e.g. socketcan can0 for a real controller)."""
    import argparse

    from .bridge import HilError

    ap = argparse.ArgumentParser(prog="python -m reeve_fmu.hil bench",
                                 description="simulated CiA 402 drive (node 1) + plant FMU on a CAN interface")
    ap.add_argument("--interface", default="socketcan", help="python-can interface (socketcan, pcan, ...)")
    ap.add_argument("--channel", default="can0")
    ap.add_argument("--bitrate", type=int, default=None, help="bit/s, for interfaces that set it (not socketcan)")
    ap.add_argument("--lockstep", action="store_true", help="lock-step instead of real time")
    ap.add_argument("--sync", choices=("bench", "controller"), default="bench",
                    help="who produces SYNC: the bench (default) or the controller (each received SYNC = one step)")
    ap.add_argument("--sync-timeout", type=float, default=None,
                    help="--sync controller: seconds without SYNC before the drive faults (default 20 periods)")
    ap.add_argument("--t-end", type=float, default=None)
    ap.add_argument("--dt", type=float, default=1e-3)
    ap.add_argument("--plant", choices=("fmu", "in-process"), default="fmu")
    ap.add_argument("--fmu", default=None)
    ap.add_argument("--start-timeout", type=float, default=300.0)
    ap.add_argument("--inject", action="append", default=[])
    ap.add_argument("--out", default="results/hil")
    a = ap.parse_args(argv)
    from .bridge import Bridge, BridgeConfig, FaultSpec, Injector

    kw = {"bitrate": a.bitrate} if a.bitrate else {}
    import can

    bus = can.Bus(interface=a.interface, channel=a.channel, **kw)
    cfg = HilConfig(plant=a.plant, fmu_path=a.fmu, dt=a.dt, realtime=not a.lockstep)
    plant = _make_plant(cfg, print)
    faults = FaultSpec.parse(a.inject)
    try:
        bridge = Bridge(bus, plant, BridgeConfig(dt=a.dt, realtime=not a.lockstep, start_timeout=a.start_timeout,
                                                 sync_source=a.sync, sync_timeout=a.sync_timeout),
                        Injector(faults, a.dt, lockstep=a.lockstep) if faults.any else None)
        n = int(math.floor((a.t_end if a.t_end is not None else 3600.0) / a.dt + 1e-9))
        print(f"bench on {a.interface}:{a.channel}: waiting for NMT start of node 1 ...")
        res = bridge.run(n)
    except HilError as exc:
        print(f"bench: {exc}", file=sys.stderr)
        return 3
    finally:
        bus.shutdown()
        plant.close()
    from ..core.results import write_csv

    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    write_csv(out / "results.csv", res.time, res.columns())
    st = res.stats
    print(json.dumps({"steps": st.steps, "deadline_misses": st.deadline_misses, "watchdog_trips": st.watchdog_trips,
                      "frames_rejected": st.frames_rejected, "brake_engaged_at": st.brake_engaged_at}))
    return 0


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] == "controller":
        return _controller_main(argv[1:])
    if argv and argv[0] == "bench":
        return _bench_main(argv[1:])
    print("usage: python -m reeve_fmu.hil controller ... | bench ... (see reeve-fmu hil --help)", file=sys.stderr)
    return 2


if __name__ == "__main__":
    sys.exit(main())
