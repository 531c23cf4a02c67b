"""The built-in controller: the demo's ElectricDrive (trip sequencer + speed/position control) as a CANopen
master on the other side of the bus.

It does what a lift controller does with a CiA 402 drive: waits for the drive's boot-up/heartbeat,
configures the drive's heartbeat consumer over SDO (0x1016:01 = controller node 0x10, 50 ms) and its max
torque (0x6072 = the drive model's torque.max, rounded up to whole per mille of 0x6076), starts the
node (NMT), and then, on every SYNC, reads TPDO1 (statusword, counter) and TPDO2 (position, velocity),
steps the ElectricDrive with that sample and answers with RPDO1: controlword (enable sequence, CST),
target torque, brake release, and the SYNC counter it answers. Every 10 ms (whole SYNC cycles) it sends
its heartbeat with a rolling counter. Every wait is bounded; `dies_at` makes it fall silent at a simulated time
(fault injection: controller-dies-at).
"""
from __future__ import annotations

import math
import struct
import time
from dataclasses import dataclass, field

from .buses import send_batch
from .protocol import (COB_EMCY, COB_HB_CONTROLLER, COB_HB_DRIVE, COB_NMT, COB_RPDO1, COB_SDO_RX, COB_SDO_TX,
                       COB_SYNC, COB_TPDO1, COB_TPDO2, CONTROLLER_NODE_ID, DRIVE_NODE_ID, MODE_CST,
                       NM_PER_PERMILLE, NMT_START, NMT_STATE_OPERATIONAL, S_FAULT, S_FAULT_REACTION_ACTIVE,
                       S_OPERATION_ENABLED, SYNC_COUNTER_MAX, controlword_for, protocol, state_from_statusword)


@dataclass
class ControllerConfig:
    dt: float = 1e-3
    n_steps: int = 1000                 # SYNC cycles to serve
    drive_values: dict | None = None    # drive FMU parameter values (reeve_fmu.components.drive.drive_params)
    dies_at: float | None = None        # s of simulated time: stop sending (dead controller)
    start_timeout: float = 60.0         # s to wait for the drive's boot-up / heartbeat
    sync_timeout: float = 5.0           # s to wait for the next SYNC before giving up
    heartbeat_ms: float = 10.0          # controller heartbeat period (rounded to whole SYNC cycles, >= 1); 0: none
    heartbeat_consumer_ms: int = 50     # written to the drive's 0x1016:01 (raised to 5 heartbeat periods)
    sdo_timeout: float = 1.0
    rt_priority: int = 0                # SCHED_FIFO priority of the controller thread while cycling (0: leave it)

    @property
    def heartbeat_every(self) -> int:
        """SYNC cycles between controller heartbeats (0: none)."""
        return max(1, round(self.heartbeat_ms * 1e-3 / self.dt)) if self.heartbeat_ms else 0

    @property
    def consumer_ms(self) -> int:
        """Consumer time for 0x1016:01: at least 5 heartbeat periods, so that a heartbeat held back by a
        few SYNC cycles of transport delay is not taken for a lost controller (with the period counted in
        SYNC cycles, a 5 ms SYNC once put the 10th-cycle heartbeat at the 50 ms consumer time itself)."""
        if not self.heartbeat_consumer_ms or not self.heartbeat_every:
            return int(self.heartbeat_consumer_ms)
        return max(int(self.heartbeat_consumer_ms), math.ceil(5 * self.heartbeat_every * self.dt * 1000.0 - 1e-9))


@dataclass
class ControllerStats:
    cycles: int = 0
    commands_sent: int = 0
    syncs_skipped: int = 0
    fault_seen_at: float | None = None
    fault_code: int | None = None
    operation_enabled_at: float | None = None
    died_at: float | None = None
    stopped: str = ""
    compute_time: list = field(default_factory=list)

    def as_dict(self) -> dict:
        import numpy as np

        ct = np.asarray(self.compute_time) if self.compute_time else np.zeros(1)
        return {"cycles": self.cycles, "commands_sent": self.commands_sent, "syncs_skipped": self.syncs_skipped,
                "fault_seen_at": self.fault_seen_at, "fault_code": self.fault_code,
                "operation_enabled_at": self.operation_enabled_at, "died_at": self.died_at,
                "stopped": self.stopped, "compute_time_p50_us": float(np.percentile(ct, 50) * 1e6),
                "compute_time_p99_us": float(np.percentile(ct, 99) * 1e6)}


def make_electric_drive(values=None):
    """The demo's drive model: reeve_fmu.components.drive.make_drive (R1, rated-load pre-torque, round trip)."""
    from ..components.drive import make_drive

    return make_drive(values)


def max_torque_permille(drive) -> int:
    """0x6072 for the drive model: its torque limit T_max (N m) in per mille of the rated torque 0x6076,
    rounded up so that the drive never rejects a command the model is allowed to give (at most the
    int16 range of the target torque 0x6071)."""
    return min(32767, int(math.ceil(drive.params.T_max / NM_PER_PERMILLE - 1e-9)))


class BuiltinController:
    def __init__(self, bus, cfg: ControllerConfig, drive=None, node_id: int = DRIVE_NODE_ID):
        import can

        self.bus = bus
        self.cfg = cfg
        self.node_id = node_id
        self.drive = drive if drive is not None else make_electric_drive(cfg.drive_values)
        self.proto = protocol()
        self.stats = ControllerStats()
        self._Message = can.Message
        self._own = frozenset({COB_RPDO1, COB_HB_CONTROLLER, COB_NMT, COB_SDO_RX})
        self.max_torque_pm = max_torque_permille(self.drive)
        self.max_torque = self.max_torque_pm * NM_PER_PERMILLE      # N m, the command clamp

    def _send(self, cob, data):
        self.bus.send(self._Message(arbitration_id=cob, data=data, is_extended_id=False))

    def _recv(self, timeout):
        """Next frame not sent by ourselves (udp_multicast echoes own frames)."""
        deadline = time.perf_counter() + timeout
        while True:
            msg = self.bus.recv(max(0.0, deadline - time.perf_counter()))
            if msg is None or msg.arbitration_id not in self._own:
                return msg

    def _sdo_download(self, index, sub, value: int, size: int = 4) -> bool:
        cmd = {1: 0x2F, 2: 0x2B, 4: 0x23}[size]
        data = struct.pack("<BHB", cmd, index, sub) + value.to_bytes(size, "little") + bytes(4 - size)
        for _ in range(3):
            self._send(COB_SDO_RX, data)
            deadline = time.perf_counter() + self.cfg.sdo_timeout
            while time.perf_counter() < deadline:
                msg = self._recv(deadline - time.perf_counter())
                if msg is None:
                    break
                if msg.arbitration_id == COB_SDO_TX and msg.data[1:4] == data[1:4]:
                    return msg.data[0] == 0x60
        return False

    def start(self) -> None:
        """Warm up the drive model, wait for the drive, configure its heartbeat consumer and max torque,
        NMT start."""
        warm = make_electric_drive(self.cfg.drive_values)
        warm.step(0.0, self.cfg.dt, 0.0, 0.0)          # compiles / loads the numba step before the clock runs
        deadline = time.perf_counter() + self.cfg.start_timeout
        while True:
            msg = self._recv(max(0.0, deadline - time.perf_counter()))
            if msg is None:
                raise TimeoutError(f"no drive heartbeat within {self.cfg.start_timeout:g} s")
            if msg.arbitration_id == COB_HB_DRIVE:
                break
        if self.cfg.consumer_ms:
            ok = self._sdo_download(0x1016, 1, (CONTROLLER_NODE_ID << 16) | self.cfg.consumer_ms)
            if not ok:
                raise RuntimeError("SDO download of 0x1016:01 (heartbeat consumer) failed")
        if not self._sdo_download(0x6072, 0, self.max_torque_pm, size=2):
            raise RuntimeError(f"SDO download of 0x6072 (max torque {self.max_torque_pm} per mille) failed")
        self._send(COB_NMT, bytes([NMT_START, self.node_id]))

    def run(self) -> ControllerStats:
        cfg = self.cfg
        st = self.stats
        try:
            self.start()
        except Exception as exc:
            st.stopped = f"start failed: {exc}"
            return st
        restore = None
        if cfg.rt_priority:
            from .bridge import set_realtime_priority

            restore = set_realtime_priority(cfg.rt_priority)
        try:
            return self._cycle(st)
        finally:
            if restore is not None:
                restore()

    def _cycle(self, st) -> ControllerStats:
        cfg = self.cfg
        dt = cfg.dt
        dec_status = self.proto.DriveStatus.decode_raw
        dec_fb = self.proto.DriveFeedback.decode
        enc_cmd = self.proto.TorqueCmd.encode
        drive = self.drive
        tmax = self.max_torque
        hb_every = cfg.heartbeat_every
        k = -1
        c_prev = None
        sw = 0
        pending = False
        alive = 0
        k_last = -1
        perf = time.perf_counter
        Msg = self._Message
        try:
            while True:
                msg = self._recv(cfg.sync_timeout)
                if msg is None:
                    st.stopped = f"no SYNC for {cfg.sync_timeout:g} s"
                    break
                cob = msg.arbitration_id
                if cob == COB_SYNC:
                    c = msg.data[0] if len(msg.data) else 0
                    if c_prev is None:
                        k = 0
                    else:
                        gap = (c - c_prev) % SYNC_COUNTER_MAX or SYNC_COUNTER_MAX
                        st.syncs_skipped += gap - 1
                        k += gap
                    c_prev = c
                    pending = True
                elif cob == COB_TPDO1:
                    try:
                        raw = dec_status(msg.data)
                    except ValueError:
                        continue
                    sw = raw[0]
                elif cob == COB_TPDO2 and pending:
                    pending = False
                    t = k * dt
                    if cfg.dies_at is not None and t >= cfg.dies_at - 1e-12:
                        st.died_at = t
                        st.stopped = "died (fault injection)"
                        break
                    try:
                        pos, vel = dec_fb(msg.data)
                    except ValueError:
                        continue
                    t0 = perf()
                    # one ElectricDrive step per cycle; across skipped SYNCs (real-time overrun) one longer step
                    tau, brake = drive.step((k_last + 1) * dt, (k - k_last) * dt, vel, pos)
                    k_last = k
                    state = state_from_statusword(sw)
                    if state in (S_FAULT, S_FAULT_REACTION_ACTIVE):
                        if st.fault_seen_at is None:
                            st.fault_seen_at = t
                        cw, tau, brake = 0, 0.0, 0.0
                    else:
                        if state == S_OPERATION_ENABLED and st.operation_enabled_at is None:
                            st.operation_enabled_at = t
                        cw = controlword_for(state)
                    tau = min(max(tau, -tmax), tmax)
                    frames = []
                    if hb_every and k % hb_every == 0:
                        frames.append(Msg(arbitration_id=COB_HB_CONTROLLER, is_extended_id=False,
                                          data=bytes([NMT_STATE_OPERATIONAL, alive])))
                        alive = (alive + 1) % 256
                    # RPDO1 last: in lock-step it closes the bench's cycle
                    frames.append(Msg(arbitration_id=COB_RPDO1, is_extended_id=False,
                                      data=enc_cmd([cw, tau, MODE_CST, 1 if brake > 0.5 else 0, c_prev])))
                    send_batch(self.bus, frames, reuse=True)
                    st.compute_time.append(perf() - t0)
                    st.commands_sent += 1
                    st.cycles = k + 1
                    if k + 1 >= cfg.n_steps:
                        st.stopped = "done"
                        break
                elif cob == COB_EMCY and len(msg.data) >= 2:
                    code = msg.data[0] | msg.data[1] << 8
                    if code and st.fault_code is None:
                        st.fault_code = code
        except Exception as exc:          # never hang the bench: report and stop
            st.stopped = f"error: {type(exc).__name__}: {exc}"
        return st
