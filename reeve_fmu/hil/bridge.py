"""The bench: a simulated CiA 402 drive in front of the plant, stepped in lock-step with SYNC or in real time.

Cycle k (t_k = k dt), the bench being the SYNC producer:

1. SYNC k: the set-points received during cycle k-1 are applied (controlword -> FSA, target torque /
   velocity, brake); the command watchdog and the heartbeat consumer are evaluated; the actuation for
   [t_k, t_k+1) is computed (CST: target torque + offset; CSV: the drive's speed PI).
2. SYNC (counter c_k = k mod 240 + 1), then TPDO1..3 with the plant outputs sampled at t_k.
3. The plant steps from t_k to t_k+1 with that actuation held.
4. The bench collects frames until the cycle ends: in lock-step when the controller's RPDO1 for c_k
   has arrived (or was consumed by fault injection, or `lockstep_timeout` of wall time passed); in real
   time at the wall-clock instant of SYNC k+1.

Transport delay: a command computed from the sample at t_k is applied over [t_k+1, t_k+2) (CiA 402:
set-points received in cycle n take effect at SYNC n+1). The controller's torque for t_k+1 is
therefore held over exactly one step: the co-simulation equivalent is the Jacobi scheme (plant and
controller both step from t_k with each other's values of t_k).

Safety (all on the drive side, independent of the controller):
* watchdog: in OPERATION ENABLED, `watchdog_cycles` (0x2030, default 3) consecutive cycles without a
  valid RPDO1 -> FAULT 0x8250: torque off, brake applied, EMCY, statusword fault bit;
* frames are rejected and counted when malformed (length), out of range (DBC limits, unsupported mode)
  or stale (RPDO1 counter != the cycle's SYNC counter; heartbeat counter not advancing by one);
* controller heartbeat consumer (0x1016): no heartbeat within the consumer time -> FAULT 0x8130;
* every wait is bounded: start (`start_timeout`), each lock-step cycle (`lockstep_timeout`; after
  `watchdog_cycles` consecutive timeouts the bench stops waiting until the controller is heard again).
"""
from __future__ import annotations

import functools
import heapq
import math
import random
import time
from dataclasses import dataclass, field

import numpy as np

from ..core.results import TimeSeries
from .buses import send_batch
from .drive402 import DriveNode
from .plants import PlantError
from .protocol import (BENCH_TX, COB_EMCY, ERR_SYNC, COB_HB_CONTROLLER, COB_HB_DRIVE, COB_NMT, COB_RPDO1, COB_RPDO2,
                       COB_SDO_RX, COB_SYNC, COB_TPDO1, COB_TPDO2, COB_TPDO3, CodecError, DRIVE_NODE_ID,
                       ERR_HEARTBEAT, ERR_PLANT, ERR_RPDO_TIMEOUT, MODE_CSV, NM_PER_PERMILLE, NMT_PREOP,
                       NMT_RESET_COMM, NMT_RESET_NODE, NMT_START, NMT_STATE_BOOT, NMT_STATE_OPERATIONAL,
                       NMT_STATE_PREOP, NMT_STATE_STOPPED, NMT_STOP, RAD_PER_INC, S_FAULT,
                       S_OPERATION_ENABLED, S_QUICK_STOP_ACTIVE, S_SWITCH_ON_DISABLED, SUPPORTED_MODES,
                       protocol, sync_counter)


class HilError(RuntimeError):
    """The bench could not run (no controller, bus failure)."""


# ---------------------------------------------------------------------------------------------------
# fault injection
# ---------------------------------------------------------------------------------------------------
@dataclass
class FaultSpec:
    loss: float = 0.0                   # probability that a cyclic controller frame is dropped
    delay_ms: float = 0.0               # transport delay of cyclic controller frames
    corrupt: float = 0.0                # probability that a cyclic controller frame is truncated
    controller_dies_at: float | None = None   # s of simulated time (the controller's side)
    seed: int = 1
    loss_from: float = 0.0              # s of simulated time from which each fault is active (KEY=V@T)
    delay_from: float = 0.0
    corrupt_from: float = 0.0

    @classmethod
    def parse(cls, items) -> "FaultSpec":
        """From CLI strings: loss=P, delay=MS, corrupt=P (each optionally @T: active from T seconds of
        simulated time on), controller-dies-at=T, seed=N."""
        spec = cls()
        for item in items or ():
            key, sep, val = str(item).partition("=")
            key = key.strip().lower().replace("_", "-")
            if not sep:
                raise ValueError(f"--inject {item!r}: expected KEY=VALUE (loss=P, delay=MS, "
                                 f"controller-dies-at=T, corrupt=P, seed=N; loss/delay/corrupt take @T)")
            val, at, t_from = val.partition("@")
            try:
                x = float(val)
                t0 = float(t_from) if at else 0.0
            except ValueError:
                raise ValueError(f"--inject {item!r}: not a number") from None
            if at and (key not in ("loss", "delay", "corrupt") or not (t0 >= 0.0 and math.isfinite(t0))):
                raise ValueError(f"--inject {item!r}: @T (seconds >= 0) applies to loss, delay and corrupt only")
            if key in ("loss", "corrupt"):
                if not 0.0 <= x <= 1.0:
                    raise ValueError(f"--inject {item}: a probability in [0, 1] is expected")
                setattr(spec, key, x)
                setattr(spec, key + "_from", t0)
            elif key == "delay":
                if not (x >= 0.0 and math.isfinite(x)):
                    raise ValueError(f"--inject {item}: milliseconds >= 0 expected")
                spec.delay_ms = x
                spec.delay_from = t0
            elif key == "controller-dies-at":
                if not (x >= 0.0 and math.isfinite(x)):
                    raise ValueError(f"--inject {item}: seconds >= 0 expected")
                spec.controller_dies_at = x
            elif key == "seed":
                spec.seed = int(x)
            else:
                raise ValueError(f"--inject {item!r}: unknown fault {key!r} (loss, delay, controller-dies-at, "
                                 f"corrupt, seed)")
        return spec

    def as_dict(self) -> dict:
        return {"loss": self.loss, "loss_from_s": self.loss_from, "delay_ms": self.delay_ms,
                "delay_from_s": self.delay_from, "corrupt": self.corrupt, "corrupt_from_s": self.corrupt_from,
                "controller_dies_at": self.controller_dies_at, "seed": self.seed}

    @property
    def any(self) -> bool:
        return bool(self.loss or self.delay_ms or self.corrupt or self.controller_dies_at is not None)


class Injector:
    """Transport faults on the cyclic frames from the controller to the bench (RPDOs, heartbeat).

    Applied where the bench receives them, with a seeded RNG, so runs are repeatable. In lock-step,
    a dropped or delayed RPDO1 ends the bench's wait for the cycle (the frame is gone or in flight),
    and the delay counts in simulated time: a frame sent in cycle k arrives in cycle
    k + floor(delay / dt) (a delay shorter than a cycle changes nothing in lock-step). In real time the
    delay is wall-clock time and a dropped frame is simply not seen."""

    CYCLIC = frozenset({COB_RPDO1, COB_RPDO2, COB_HB_CONTROLLER})

    def __init__(self, spec: FaultSpec, dt: float, lockstep: bool):
        self.spec = spec
        self.dt = dt
        self.lockstep = lockstep
        self.rng = random.Random(spec.seed)
        self.delay_cycles = int(math.floor(spec.delay_ms * 1e-3 / dt + 1e-9)) if lockstep else 0
        self.delay_s = spec.delay_ms * 1e-3
        self._held: list = []          # heap of (release key, seq, msg)
        self._seq = 0
        self.lost = self.delayed = self.corrupted = 0

    def on_frame(self, msg, cycle: int, now: float):
        """-> (msg or None to deliver now, whether the frame was consumed by a fault)."""
        if msg.arbitration_id not in self.CYCLIC:
            return msg, False
        s = self.spec
        t = cycle * self.dt + 1e-12
        if s.loss and t >= s.loss_from and self.rng.random() < s.loss:
            self.lost += 1
            return None, True
        if s.corrupt and t >= s.corrupt_from and self.rng.random() < s.corrupt:
            self.corrupted += 1
            msg = _copy_msg(msg, bytes(msg.data[:-1]))
        if s.delay_ms and t >= s.delay_from:
            if self.lockstep and self.delay_cycles > 0:
                self.delayed += 1
                self._push(cycle + self.delay_cycles, msg)
                return None, True
            if not self.lockstep:
                self.delayed += 1
                self._push(now + self.delay_s, msg)
                return None, False
        return msg, False

    def _push(self, key, msg):
        self._seq += 1
        heapq.heappush(self._held, (key, self._seq, msg))

    def due(self, key) -> list:
        out = []
        while self._held and self._held[0][0] <= key:
            out.append(heapq.heappop(self._held)[2])
        return out

    def next_release(self) -> float:
        return self._held[0][0] if self._held else math.inf


def effective_rt_priority(rt_priority: int | None, realtime: bool) -> int:
    """None -> 50 in real time (wake-ups on time despite other load), 0 (normal scheduling) in lock-step."""
    if rt_priority is None:
        return 50 if realtime else 0
    return int(rt_priority)


def set_realtime_priority(priority: int):
    """SCHED_FIFO for the calling thread (Linux, needs root or CAP_SYS_NICE); returns a function that
    restores the previous policy, or None when not possible. The loops block in recv() with timeouts,
    so a FIFO thread never spins."""
    import os

    try:
        old_policy = os.sched_getscheduler(0)
        old_param = os.sched_getparam(0)
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(int(priority)))
    except (AttributeError, OSError, PermissionError):
        return None

    def restore():
        try:
            os.sched_setscheduler(0, old_policy, old_param)
        except OSError:
            pass
    return restore


def _copy_msg(msg, data: bytes):
    import can

    return can.Message(arbitration_id=msg.arbitration_id, data=data, is_extended_id=False,
                       timestamp=msg.timestamp)


# ---------------------------------------------------------------------------------------------------
# the bench
# ---------------------------------------------------------------------------------------------------
@dataclass
class BridgeConfig:
    dt: float = 1e-3                    # SYNC period [s] (0x1006)
    realtime: bool = False              # pace SYNC to the wall clock instead of lock-step
    lockstep_timeout: float = 0.5       # s of wall time a lock-step cycle waits for RPDO1
    start_timeout: float = 60.0         # s of wall time to wait for NMT start
    heartbeat_wall_period: float = 0.1  # s, drive heartbeat while waiting for NMT start
    record: bool = True
    sync_source: str = "bench"          # "bench": the bench produces SYNC; "controller": a received SYNC starts each cycle
    sync_timeout: float | None = None   # controller SYNC: wall time without SYNC -> fault (None: 20 periods, >= 50 ms)
    rt_priority: int | None = None      # SCHED_FIFO priority of the bench thread; None: 50 in real time, off in lock-step
    stop_when_safe: bool = False        # end the run 1 s after a fault reaction has stopped the machine
    node_id: int = DRIVE_NODE_ID


@dataclass
class BridgeStats:
    steps: int = 0
    frames_rx: int = 0
    frames_ignored: int = 0
    rejected_malformed: int = 0
    rejected_out_of_range: int = 0
    rejected_stale: int = 0
    commands_valid: int = 0
    commands_missing: int = 0
    watchdog_trips: int = 0
    heartbeat_faults: int = 0
    heartbeat_gaps: int = 0
    lockstep_timeouts: int = 0
    deadline_misses: int = 0
    sdo_requests: int = 0
    emcy_sent: int = 0
    fault_code: int = 0
    fault_at: float | None = None
    brake_engaged_at: float | None = None
    brake_closed_at: float | None = None
    machine_stopped_at: float | None = None       # first |motor.speed| < 0.01 rad/s after the fault
    stop_distance: float | None = None            # car travel from the fault to machine_stopped_at
    car_excursion: float | None = None            # largest |car position - position at the fault| after it
    car_speed_at_fault: float | None = None
    plant_error: str | None = None
    rt_priority: bool = False
    started_wall: float = 0.0
    wall: float = 0.0
    step_time: np.ndarray = field(default_factory=lambda: np.zeros(0))     # per cycle, s
    sync_jitter: np.ndarray = field(default_factory=lambda: np.zeros(0))   # real time only, s

    @property
    def frames_rejected(self) -> int:
        return self.rejected_malformed + self.rejected_out_of_range + self.rejected_stale


class Bridge:
    """Simulated CiA 402 drive + plant on a python-can bus (see the module docstring)."""

    def __init__(self, bus, plant, config: BridgeConfig | None = None, injector: Injector | None = None,
                 drive_node: DriveNode | None = None, clock=None):
        self.bus = bus
        # the wall clock of real time and of every bounded wait (a simulated clock makes real time exact in tests)
        self.clock = clock or time.perf_counter
        self.plant = plant
        self.cfg = config or BridgeConfig()
        self.inj = injector
        self.proto = protocol()
        self.dn = drive_node or DriveNode(self.cfg.node_id)
        self.dn.attach(bus)
        self.drive = self.dn.drive
        self.stats = BridgeStats()
        names = list(plant.output_names)
        self.output_names = names

        def idx(n):
            return names.index(n) if n in names else None
        self._iw, self._ia = idx("motor.speed"), idx("motor.angle")
        if self._iw is None or self._ia is None:
            raise HilError("the plant has no motor.speed/motor.angle outputs")
        self._it, self._ix = idx("traction.tension_in"), idx("car.position")
        self._iv, self._ib = idx("car.velocity"), idx("brake.engaged")
        self._can = __import__("can")
        self._k = -1                          # current cycle (-1 before the first SYNC)
        self._cmd = None                      # valid RPDO1 raw values of the current cycle
        self._vel = None                      # valid RPDO2 raw values of the current cycle
        self._closed = False                  # lock-step: the cycle's RPDO1 has been handled
        self._missed = 0
        self._rejected_in_cycle = False
        self._hb_last_k = None                # cycle of the last controller heartbeat
        self._hb_counter = None
        self._hb_seen = False
        self._hb_lost = False
        self._consec_timeouts = 0
        self._drive_hb_counter = 0
        self._last_cmd_valid = False
        self._brake_applied = True
        self._torque = 0.0
        self._warm = False
        self._ext = self.cfg.sync_source == "controller"
        if self.cfg.sync_source not in ("bench", "controller"):
            raise ValueError(f"sync_source must be 'bench' or 'controller', got {self.cfg.sync_source!r}")
        self._sync_rx = None                  # data of a SYNC received from the controller (external SYNC)
        self._sync_lost = False
        self._counter = None                  # SYNC counter of the current cycle (None: no counter check)

    # -- frames -----------------------------------------------------------------------------------------
    def _send(self, cob: int, data: bytes) -> None:
        self.bus.send(self._can.Message(arbitration_id=cob, data=data, is_extended_id=False))

    def _service(self, msg) -> None:
        """Handle one received frame (after fault injection)."""
        cob = msg.arbitration_id
        if msg.is_error_frame or msg.is_remote_frame or msg.is_extended_id:
            return
        if cob == COB_SYNC and self._ext:
            self._sync_rx = bytes(msg.data)
            return
        if cob in BENCH_TX:
            return
        st = self.stats
        st.frames_rx += 1
        data = msg.data
        if cob == COB_RPDO1:
            self._on_rpdo1(data)
        elif cob == COB_RPDO2:
            self._on_rpdo2(data)
        elif cob == COB_HB_CONTROLLER:
            self._on_heartbeat(data)
        elif cob == COB_SDO_RX:
            st.sdo_requests += 1
            self.dn.on_sdo(cob, data, msg.timestamp)
        elif cob == COB_NMT:
            self._on_nmt(data)
        else:
            st.frames_ignored += 1

    def _reject(self, kind: str) -> None:
        setattr(self.stats, "rejected_" + kind, getattr(self.stats, "rejected_" + kind) + 1)
        self._rejected_in_cycle = True

    def _rpdo(self, codec, data, answer: bool):
        """The raw signals of an RPDO, or None: ignored outside OPERATIONAL, rejected when malformed
        (`answer`: the frame is the controller's answer to this cycle, broken or not)."""
        if self.dn.nmt_state != NMT_STATE_OPERATIONAL or self._k < 0:
            self.stats.frames_ignored += 1           # PDOs are only processed in OPERATIONAL
            return None
        try:
            return codec.decode_raw(data)
        except CodecError:
            self._reject("malformed")
            if answer:
                self._closed = True
            return None

    def _on_rpdo1(self, data) -> None:
        codec = self.proto.TorqueCmd
        raw = self._rpdo(codec, data, True)
        if raw is None:
            return
        if self.dn.params["counter_check"] and self._counter is not None and raw[4] != self._counter:
            self._reject("stale")                     # an answer to an older SYNC: keep waiting
            return
        if codec.in_range(raw) is not None or raw[2] not in (0,) + SUPPORTED_MODES \
                or abs(raw[1] * NM_PER_PERMILLE) > self.drive.max_torque + 1e-9:
            self._reject("out_of_range")
            self._closed = True
            return
        self._cmd = raw
        self._closed = True

    def _on_rpdo2(self, data) -> None:
        codec = self.proto.VelocityCmd
        raw = self._rpdo(codec, data, False)
        if raw is None:
            return
        if codec.in_range(raw) is not None:
            self._reject("out_of_range")
            return
        self._vel = raw

    def _on_heartbeat(self, data) -> None:
        if len(data) not in (1, 2):
            self._reject("malformed")
            return
        if len(data) == 2:
            # rolling counter: it must advance (a repeat or a step back = stale/replayed frame); a jump
            # forward means heartbeats were lost, which the consumer time judges
            cnt = data[1]
            if self._hb_counter is not None:
                step = (cnt - self._hb_counter) % 256
                if step == 0 or step >= 128:
                    self._reject("stale")
                    return
                if step > 1:
                    self.stats.heartbeat_gaps += 1
            self._hb_counter = cnt
        self._hb_seen = True
        self._hb_last_k = self._k

    def _on_nmt(self, data) -> None:
        if len(data) != 2:
            self._reject("malformed")
            return
        cmd, node = data[0], data[1]
        if node not in (0, self.cfg.node_id):
            return
        dn = self.dn
        if cmd == NMT_START:
            dn.nmt_state = NMT_STATE_OPERATIONAL
        elif cmd == NMT_STOP:
            dn.nmt_state = NMT_STATE_STOPPED
        elif cmd == NMT_PREOP:
            dn.nmt_state = NMT_STATE_PREOP
        elif cmd in (NMT_RESET_NODE, NMT_RESET_COMM):
            dn.nmt_state = NMT_STATE_PREOP
            self._send(COB_HB_DRIVE, bytes([NMT_STATE_BOOT]))
            if cmd == NMT_RESET_NODE and self.drive.state != S_FAULT:
                self.drive.state = S_SWITCH_ON_DISABLED

    # -- start -------------------------------------------------------------------------------------------
    def warm_up(self) -> None:
        """Step the plant once and back (numba compile/cache load) before any clock runs; idempotent."""
        if not self._warm and hasattr(self.plant, "warm_up"):
            self.plant.warm_up(self.cfg.dt)
        self._warm = True

    def wait_for_start(self, alive=None) -> float:
        """Boot-up message, then pre-operational heartbeats until a master sends NMT start (bounded).
        alive(): None while the controller may still come, else the reason why it will not."""
        self._send(COB_HB_DRIVE, bytes([NMT_STATE_BOOT]))
        t0 = self.clock()
        deadline = t0 + self.cfg.start_timeout
        next_hb = t0
        while self.dn.nmt_state != NMT_STATE_OPERATIONAL:
            now = self.clock()
            if now >= deadline:
                raise HilError(f"no controller started the drive (NMT start to node {self.cfg.node_id}) "
                               f"within {self.cfg.start_timeout:g} s")
            why = alive() if alive is not None else None
            if why:
                raise HilError(f"the controller stopped before starting the drive: {why}")
            if now >= next_hb:
                self._heartbeat()
                next_hb = now + self.cfg.heartbeat_wall_period
            msg = self.bus.recv(max(0.0, min(deadline, next_hb, now + 0.05) - now))
            if msg is not None:
                self._service(msg)
        return self.clock() - t0

    def _heartbeat(self) -> None:
        self._send(COB_HB_DRIVE, bytes([self.dn.nmt_state, self._drive_hb_counter]))
        self._drive_hb_counter = (self._drive_hb_counter + 1) % 256

    # -- cycle ---------------------------------------------------------------------------------------------
    def _fault(self, code: int, t: float) -> None:
        if self.drive.fault(code):
            st = self.stats
            if st.fault_at is None:
                st.fault_at = t
                st.fault_code = code
            if st.brake_engaged_at is None:
                st.brake_engaged_at = t
            data = self.proto.EMCY.encode([code, self.drive.error_register, self.drive.state, max(t, 0.0)])
            self._send(COB_EMCY, data)
            st.emcy_sent += 1

    def _at_sync(self, k: int, t: float) -> None:
        """Apply what cycle k-1 delivered; watchdog; heartbeat consumer; automatic FSA transitions."""
        d = self.drive
        dn = self.dn
        armed = d.state == S_OPERATION_ENABLED
        d.at_sync()
        cmd, self._cmd = self._cmd, None
        vel, self._vel = self._vel, None
        if cmd is not None:
            cw, tq, mode, brake, _ = cmd
            self.stats.commands_valid += 1
            d.target_torque = tq * NM_PER_PERMILLE
            d.brake_release = bool(brake)
            if mode:
                d.set_mode(mode)
            d.apply_controlword(cw)
            self._missed = 0
            self._last_cmd_valid = True
        else:
            self._last_cmd_valid = False
            if armed and k > 0:
                self._missed += 1
                self.stats.commands_missing += 1
                if self._missed >= dn.params["watchdog_cycles"]:
                    self.stats.watchdog_trips += 1
                    self._fault(ERR_RPDO_TIMEOUT, t)
        if vel is not None:
            d.target_velocity = vel[0] * RAD_PER_INC
            d.torque_offset = vel[1] * NM_PER_PERMILLE
        # heartbeat consumer (0x1016:01 = node << 16 | ms); monitoring starts with the first heartbeat
        hb = dn.params["heartbeat_consumer"]
        if hb and self._hb_seen and self._hb_last_k is not None:
            limit_ms = hb & 0xFFFF
            if limit_ms and (k - self._hb_last_k) * self.cfg.dt * 1000.0 > limit_ms + 1e-9:
                if not self._hb_lost:
                    self._hb_lost = True
                    if d.state == S_OPERATION_ENABLED or d.state == S_QUICK_STOP_ACTIVE:
                        self.stats.heartbeat_faults += 1
                        self._fault(ERR_HEARTBEAT, t)
            else:
                self._hb_lost = False
        d.warning = (self._missed > 0) or self._hb_lost

    def run(self, n_steps: int, progress=None, alive=None, stop=None) -> "BridgeResult":
        """Wait for NMT start, then run n_steps SYNC cycles; returns the recorded signals and statistics.
        alive(): see wait_for_start; stop: a threading.Event that ends the run early (checked every cycle)."""
        cfg = self.cfg
        dt = cfg.dt
        st = self.stats
        self.warm_up()
        st.started_wall = self.wait_for_start(alive)
        prio = effective_rt_priority(cfg.rt_priority, cfg.realtime)
        restore = set_realtime_priority(prio) if prio else None
        st.rt_priority = restore is not None
        try:
            return self._run(n_steps, progress, stop)
        finally:
            if restore is not None:
                restore()

    def _run(self, n_steps, progress, stop) -> "BridgeResult":
        cfg = self.cfg
        dt = cfg.dt
        st = self.stats
        n = int(n_steps)
        nout = len(self.output_names)
        rec = cfg.record
        Y = np.empty((n + 1, nout)) if rec else None
        H = np.empty((n + 1, 8)) if rec else None          # torque, brake, state, statusword, valid, missed, flags, mode
        step_time = np.zeros(n)
        jitter = np.zeros(n) if cfg.realtime else None
        y = self.plant.outputs()
        hb_every = max(1, int(round(self.dn.params["heartbeat_producer_ms"] * 1e-3 / dt))) \
            if self.dn.params["heartbeat_producer_ms"] else 0
        tp1, tp2, tp3 = (e if 1 <= e <= 240 else 0 for e in self.dn.params["tpdo_every"])
        proto = self.proto
        enc_status, enc_fb, enc_plant = proto.DriveStatus.encode, proto.DriveFeedback.encode, proto.PlantStatus.encode
        iw, ia, it, ix, iv, ib = self._iw, self._ia, self._it, self._ix, self._iv, self._ib
        Message = self._can.Message
        send_frames = functools.partial(send_batch, self.bus, reuse=True)
        d = self.drive
        dn = self.dn
        perf = self.clock
        t_wall0 = perf()
        t_prev_sync = t_wall0
        sync_timeout = cfg.sync_timeout if cfg.sync_timeout is not None else max(20 * dt, 0.05)
        k_done = n
        x_fault = None
        for k in range(n):
            t = k * dt
            if stop is not None and stop.is_set():
                k_done = k
                break
            if self._ext and not self._sync_lost:
                got = self._wait_external_sync(sync_timeout)
                t_sync = perf()
                if got is None:                       # the SYNC producer fell silent: fault, then own clock
                    self._sync_lost = True
                    self._k = k
                    self._fault(ERR_SYNC, t)
                    t_wall0 = t_sync - k * dt
                    self._counter = None
                else:
                    self._counter = got[0] if got else None
                    if jitter is not None:
                        jitter[k] = (t_sync - t_prev_sync - dt) if k else 0.0
                t_prev_sync = t_sync
            elif cfg.realtime or self._sync_lost:
                self._wait_until(t_wall0 + k * dt)
                t_sync = perf()
                if jitter is not None:
                    jitter[k] = t_sync - (t_wall0 + k * dt)
            else:
                t_sync = perf()
            if not self._ext:
                self._counter = sync_counter(k)
            self._k = k
            self._at_sync(k, t)
            w = y[iw]
            torque, brake = d.actuation(w, dt)
            self._torque = torque
            self._brake_applied = brake < 0.5
            c = self._counter if self._counter is not None else sync_counter(k)
            brake_engaged = ib is not None and y[ib] > 0.5
            flags = ((1 if self._brake_applied else 0) | (2 if brake_engaged else 0)
                     | (4 if st.watchdog_trips else 0) | (8 if self._hb_lost else 0)
                     | (16 if st.plant_error else 0) | (32 if self._rejected_in_cycle else 0)
                     | (64 if self._missed else 0) | (128 if d.state == S_QUICK_STOP_ACTIVE else 0))
            self._rejected_in_cycle = False
            sw = d.statusword(brake_released=not self._brake_applied)
            live = dn.live
            pos_inc = round(y[ia] / RAD_PER_INC)
            vel_inc = round(w / RAD_PER_INC)
            tq_pm = round(torque / NM_PER_PERMILLE)
            live[0x6064], live[0x606C], live[0x6077], live[0x2110], live[0x2111] = pos_inc, vel_inc, tq_pm, flags, c
            frames = [] if self._ext else [Message(arbitration_id=COB_SYNC, data=bytes((c,)), is_extended_id=False)]
            if dn.nmt_state == NMT_STATE_OPERATIONAL and not self._sync_lost:
                if tp1 and k % tp1 == 0:
                    frames.append(Message(arbitration_id=COB_TPDO1, is_extended_id=False, data=enc_status(
                        [sw, tq_pm * NM_PER_PERMILLE, d.mode, flags & 1, (flags >> 1) & 1, (flags >> 2) & 1,
                         (flags >> 3) & 1, (flags >> 4) & 1, (flags >> 5) & 1, (flags >> 6) & 1, flags >> 7, c,
                         d.error_register], strict=False)))
                if tp2 and k % tp2 == 0:
                    frames.append(Message(arbitration_id=COB_TPDO2, is_extended_id=False, data=enc_fb(
                        [pos_inc * RAD_PER_INC, vel_inc * RAD_PER_INC], strict=False)))
                if tp3 and k % tp3 == 0:
                    tension = y[it] if it is not None else 0.0
                    xcar = y[ix] if ix is not None else 0.0
                    frames.append(Message(arbitration_id=COB_TPDO3, is_extended_id=False, data=enc_plant(
                        [min(max(tension, -2e7), 2e7), min(max(xcar, -2000.0), 2000.0)], strict=False)))
            if frames:
                send_frames(frames)
            if hb_every and k % hb_every == 0:
                self._heartbeat()
            if rec:
                Y[k] = y
                H[k] = (torque, brake, d.state, sw, self._last_cmd_valid, self._missed, flags, d.mode)
            # safety bookkeeping on the plant's feedback after a fault reaction
            if st.brake_engaged_at is not None:
                if st.brake_closed_at is None and brake_engaged:
                    st.brake_closed_at = t
                if x_fault is None:
                    x_fault = y[ix] if ix is not None else 0.0
                    st.car_speed_at_fault = float(y[iv]) if iv is not None else None
                if ix is not None:
                    st.car_excursion = max(st.car_excursion or 0.0, float(abs(y[ix] - x_fault)))
                if st.machine_stopped_at is None and abs(w) < 0.01:
                    st.machine_stopped_at = t
                    st.stop_distance = float(abs(y[ix] - x_fault)) if ix is not None else None
                if cfg.stop_when_safe and st.machine_stopped_at is not None and t >= st.machine_stopped_at + 1.0:
                    k_done = k
                    break
            # plant step
            try:
                y = self.plant.step(dt, torque, brake)
            except PlantError as exc:
                st.plant_error = str(exc)
                self._fault(ERR_PLANT, t)
                k_done = k + 1
                break
            done = perf()
            step_time[k] = done - t_sync
            if self._ext and not self._sync_lost:
                if cfg.realtime and done - t_sync > dt:
                    st.deadline_misses += 1             # the work did not fit into one SYNC period
            elif cfg.realtime or self._sync_lost:
                if done > t_wall0 + (k + 1) * dt:
                    st.deadline_misses += 1
            else:
                self._wait_lockstep(k)
            if progress is not None and k % 1000 == 0:
                progress(t)
        st.steps = k_done
        st.wall = perf() - t_wall0
        if rec:
            Y[k_done] = y
            H[k_done] = H[k_done - 1] if k_done > 0 else 0.0
        st.step_time = step_time[:k_done]
        if jitter is not None:
            st.sync_jitter = jitter[:k_done]
        return self._result(Y, H, k_done)

    def _result(self, Y, H, k_done: int) -> "BridgeResult":
        """The run's record (None without recording: Y is None), statistics and injected faults."""
        inj = self.inj
        injected = {"lost": inj.lost, "delayed": inj.delayed, "corrupted": inj.corrupted} if inj is not None \
            else {"lost": 0, "delayed": 0, "corrupted": 0}
        record = None
        if Y is not None:
            cols = {n: Y[:k_done + 1, i] for i, n in enumerate(self.output_names)}
            cols.update({n: H[:k_done + 1, i] for i, n in enumerate(HIL_COLUMNS)})
            record = TimeSeries(np.arange(k_done + 1) * self.cfg.dt, cols)
        return BridgeResult(record=record, stats=self.stats, injected=injected)

    # -- waiting ---------------------------------------------------------------------------------------------
    def _wait_lockstep(self, k: int) -> None:
        """Collect frames until the controller's RPDO1 for cycle k (bounded by lockstep_timeout)."""
        self._closed = False
        inj = self.inj
        if inj is not None and inj.lockstep:
            for m in inj.due(k):
                self._service(m)
        poll = self._consec_timeouts >= self.dn.params["watchdog_cycles"]
        timeout = 0.0 if poll else self.cfg.lockstep_timeout
        deadline = self.clock() + timeout
        recv = self.bus.recv
        heard = False
        while not self._closed:
            remaining = deadline - self.clock()
            if remaining < 0.0:
                remaining = 0.0
            msg = recv(remaining)
            if msg is None:
                if not poll:
                    self.stats.lockstep_timeouts += 1
                    self._consec_timeouts += 1
                break
            heard = heard or msg.arbitration_id in (COB_RPDO1, COB_RPDO2, COB_HB_CONTROLLER, COB_SDO_RX)
            if inj is not None:
                cob = msg.arbitration_id
                m2, consumed = inj.on_frame(msg, k, self.clock())
                if m2 is None:
                    if consumed and cob == COB_RPDO1:
                        self._closed = True     # dropped or in flight: no answer for this cycle
                    continue
                msg = m2
            self._service(msg)
        if self._closed or heard:
            self._consec_timeouts = 0

    def _wait_external_sync(self, timeout: float):
        """Collect frames until the controller's SYNC arrives; its data (b'' without counter), or None
        after `timeout` s of silence (bounded)."""
        recv = self.bus.recv
        inj = self.inj
        perf = self.clock
        deadline = perf() + timeout
        while self._sync_rx is None:
            now = perf()
            if inj is not None and not inj.lockstep:
                for m in inj.due(now):
                    self._service(m)
            if now >= deadline:
                return None
            nxt = deadline if inj is None or inj.lockstep else min(deadline, inj.next_release())
            msg = recv(max(0.0, nxt - now))
            if msg is None:
                continue
            if inj is not None:
                m2, consumed = inj.on_frame(msg, self._k, perf())
                if m2 is None:
                    continue
                msg = m2
            self._service(msg)
        data, self._sync_rx = self._sync_rx, None
        return data

    def _wait_until(self, until: float) -> None:
        """Real time: collect frames until the wall-clock instant `until` (and release delayed ones)."""
        recv = self.bus.recv
        inj = self.inj
        perf = self.clock
        while True:
            now = perf()
            if inj is not None and not inj.lockstep:
                for m in inj.due(now):
                    self._service(m)
                nxt = min(until, inj.next_release())
            else:
                nxt = until
            if now >= until:
                return
            msg = recv(max(0.0, nxt - now))
            if msg is not None:
                if inj is not None:
                    msg, _ = inj.on_frame(msg, self._k, perf())
                    if msg is None:
                        continue
                self._service(msg)


HIL_COLUMNS = ("hil.torque", "hil.brake_command", "hil.state", "hil.statusword", "hil.command_valid",
               "hil.commands_missed", "hil.flags", "hil.mode")


@dataclass
class BridgeResult:
    """A bench run: `record`, a TimeSeries of the plant outputs and HIL_COLUMNS at every SYNC (None
    without recording), the statistics and the injected faults."""
    record: TimeSeries | None
    stats: BridgeStats
    injected: dict

    def column(self, name: str) -> np.ndarray:
        return self.record[name]
