"""Drive side of CiA 402: the state machine, the cyclic synchronous modes and the object dictionary.

`Drive402` is the drive logic without any bus or plant: controlword -> FSA transitions, fault and quick
stop reactions, set-points of CST (target torque + torque offset) and CSV (the drive's own speed PI on
target velocity + velocity feedback), brake control, statusword. `DriveNode` exposes it as a CANopen
slave: a canopen `LocalNode` with the packaged EDS whose SDO server reads and writes the live objects
(0x6040/0x6041/0x6060/0x6061/0x6064/0x606C/0x6071/0x6077/0x60FF/...), so a master using canopen's
`BaseNode402` (or any CANopen master) configures and commands it like a real drive.

States follow CiA 402 (transition numbers in comments). Reactions chosen for an elevator drive:
* quick stop (transition 11): torque off and the machine brake applied at once (the emergency stop of a
  lift opens the safety chain); the drive stays in QUICK STOP ACTIVE until "disable voltage" (12) or
  "enable operation" (16);
* fault (13): FAULT REACTION ACTIVE for one cycle (torque off, brake applied), then FAULT (14); a rising
  edge of controlword bit 7 resets it to SWITCH ON DISABLED (15);
* the brake is released only in OPERATION ENABLED while the controller asks for it (0x2100 bit 0).
"""
from __future__ import annotations

import math

from .protocol import (CW_FAULT_RESET, ERR_HEARTBEAT, ERR_NONE, ERR_PLANT, ERR_RPDO_TIMEOUT, MODE_CSV, MODE_CST,
                       NM_PER_PERMILLE, NMT_STATE_PREOP, RAD_PER_INC, S_FAULT, S_FAULT_REACTION_ACTIVE,
                       S_NOT_READY, S_OPERATION_ENABLED, S_QUICK_STOP_ACTIVE, S_READY_TO_SWITCH_ON,
                       S_SWITCH_ON_DISABLED, S_SWITCHED_ON, STATE_SW, SUPPORTED_MODES, SW_BRAKE_RELEASED,
                       SW_FOLLOWING, SW_REMOTE, SW_TARGET_REACHED, SW_WARNING, load_eds)


class Drive402:
    """CiA 402 FSA + CST/CSV set-point processing of one axis. Units: N m, rad/s, s."""

    def __init__(self, *, max_torque: float = 1819 * NM_PER_PERMILLE, csv_kp: float = 970.0,
                 csv_ti: float = 0.127, mode: int = MODE_CST):
        self.max_torque = float(max_torque)
        self.csv_kp = float(csv_kp)
        self.csv_ti = float(csv_ti)
        self.state = S_NOT_READY
        self.mode = mode
        self.controlword = 0
        self.target_torque = 0.0
        self.torque_offset = 0.0
        self.target_velocity = 0.0
        self.brake_release = False
        self.error_code = ERR_NONE
        self.warning = False
        self._integ = 0.0
        self.transitions = 0
        self.state = S_SWITCH_ON_DISABLED        # transition 1 after the internal initialisation

    # -- FSA ----------------------------------------------------------------------------------------
    def apply_controlword(self, cw: int) -> None:
        """Process a controlword (CiA 402 table of device control commands)."""
        prev = self.controlword
        self.controlword = cw
        s = self.state
        new = s
        if s == S_FAULT:
            if cw & CW_FAULT_RESET and not prev & CW_FAULT_RESET:
                new = S_SWITCH_ON_DISABLED                                    # 15
                self.error_code = ERR_NONE
        elif s == S_FAULT_REACTION_ACTIVE or cw & CW_FAULT_RESET:
            pass                               # bit 7 set outside FAULT: no command (CiA 402)
        elif cw & 0x02 == 0:                   # disable voltage
            if s in (S_READY_TO_SWITCH_ON, S_SWITCHED_ON, S_OPERATION_ENABLED, S_QUICK_STOP_ACTIVE):
                new = S_SWITCH_ON_DISABLED                                    # 7, 9, 10, 12
        elif cw & 0x04 == 0:                   # quick stop (xxxx x01x)
            if s == S_OPERATION_ENABLED:
                new = S_QUICK_STOP_ACTIVE                                     # 11
            elif s in (S_READY_TO_SWITCH_ON, S_SWITCHED_ON):
                new = S_SWITCH_ON_DISABLED                                    # 7, 10
        elif cw & 0x01 == 0:                   # shutdown (xxxx x110)
            if s in (S_SWITCH_ON_DISABLED, S_SWITCHED_ON, S_OPERATION_ENABLED):
                new = S_READY_TO_SWITCH_ON                                    # 2, 6, 8
        elif cw & 0x08 == 0:                   # switch on / disable operation (xxxx 0111)
            if s == S_READY_TO_SWITCH_ON:
                new = S_SWITCHED_ON                                           # 3
            elif s == S_OPERATION_ENABLED:
                new = S_SWITCHED_ON                                           # 5
        else:                                  # enable operation (xxxx 1111)
            if s == S_READY_TO_SWITCH_ON:
                new = S_SWITCHED_ON                                           # 3 (4 follows next cycle)
            elif s in (S_SWITCHED_ON, S_QUICK_STOP_ACTIVE):
                new = S_OPERATION_ENABLED                                     # 4, 16
        if new != s:
            self._enter(new)

    def _enter(self, new: int) -> None:
        if new == S_OPERATION_ENABLED:
            self._integ = 0.0
        self.state = new
        self.transitions += 1

    def fault(self, code: int) -> bool:
        """Fault reaction (transition 13); True if this call entered it."""
        if self.state in (S_FAULT_REACTION_ACTIVE, S_FAULT):
            return False
        self.error_code = code
        self._enter(S_FAULT_REACTION_ACTIVE)
        return True

    def at_sync(self) -> None:
        """Automatic transitions evaluated once per SYNC (FAULT REACTION ACTIVE -> FAULT, 14)."""
        if self.state == S_FAULT_REACTION_ACTIVE:
            self._enter(S_FAULT)

    def set_mode(self, mode: int) -> bool:
        if mode in SUPPORTED_MODES:
            if mode != self.mode:
                self._integ = 0.0
            self.mode = mode
            return True
        return False

    # -- cyclic ---------------------------------------------------------------------------------------
    def actuation(self, speed: float, dt: float) -> tuple[float, float]:
        """(motor torque N m, brake command 1 release / 0 apply) to hold over the coming cycle."""
        if self.state != S_OPERATION_ENABLED:
            self._integ = 0.0
            return 0.0, 0.0
        tmax = self.max_torque
        if self.mode == MODE_CSV:
            e = self.target_velocity - speed
            u = self.csv_kp * e + self._integ + self.torque_offset
            if u > tmax:
                tq = tmax
            elif u < -tmax:
                tq = -tmax
            else:
                tq = u
            if self.csv_ti > 0 and math.isfinite(self.csv_ti) and not ((u > tmax and e > 0) or (u < -tmax and e < 0)):
                self._integ += self.csv_kp / self.csv_ti * e * dt
        else:
            tq = self.target_torque + self.torque_offset
            tq = tmax if tq > tmax else (-tmax if tq < -tmax else tq)
        return tq, (1.0 if self.brake_release else 0.0)

    def statusword(self, brake_released: bool = False, target_reached: bool = False) -> int:
        sw = STATE_SW[self.state] | SW_REMOTE
        if self.warning:
            sw |= SW_WARNING
        if brake_released:
            sw |= SW_BRAKE_RELEASED
        if self.state == S_OPERATION_ENABLED:
            sw |= SW_FOLLOWING
            if target_reached:
                sw |= SW_TARGET_REACHED
        return sw

    @property
    def error_register(self) -> int:
        if self.error_code == ERR_NONE:
            return 0
        reg = 0x01                                                     # generic error
        if self.error_code in (ERR_RPDO_TIMEOUT, ERR_HEARTBEAT):
            reg |= 0x10                                                # communication error
        if self.error_code == ERR_PLANT:
            reg |= 0x80                                                # manufacturer specific
        return reg


class DriveNode:
    """The drive as a CANopen slave: canopen LocalNode (SDO server on the EDS) around a Drive402.

    The bench feeds it the frames of its SDO COB-ID (`on_sdo`); live values are read from `drive` and
    from `live` (position/velocity increments, torque per mille, flags, counters) which the bench
    refreshes every SYNC. Writes to the set-point objects go straight into `drive`."""

    LIVE_DEFAULTS = {0x6064: 0, 0x606C: 0, 0x6077: 0, 0x2110: 0, 0x2111: 0, 0x2120: 0, 0x2121: 0,
                     0x2031: 0, 0x2032: 0}

    def __init__(self, node_id: int = 1, od=None):
        import canopen
        from canopen.sdo import SdoAbortedError

        self._abort = SdoAbortedError
        self.od = od if od is not None else load_eds(node_id)
        self.node = canopen.LocalNode(node_id, self.od)
        # heartbeats are produced by the bench in simulated time, not by canopen's wall-clock thread
        if self.node.nmt.on_write in self.node._write_callbacks:
            self.node._write_callbacks.remove(self.node.nmt.on_write)
        d = self.od
        self.drive = Drive402(max_torque=d[0x6072].default * NM_PER_PERMILLE, csv_kp=d[0x2040].default,
                              csv_ti=d[0x2041].default, mode=d[0x6060].default)
        self.live = dict(self.LIVE_DEFAULTS)
        self.params = {
            "watchdog_cycles": int(d[0x2030].default),
            "counter_check": bool(d[0x2033].default),
            "heartbeat_consumer": int(d[0x1016][1].default),
            "heartbeat_producer_ms": int(d[0x1017].default),
            "cycle_period_us": int(d[0x1006].default),
            # TPDO1..3 transmission types: n = every n-th SYNC (1..240); other values: not sent cyclically
            "tpdo_every": [int(d[0x1800 + i][2].default) for i in range(3)],
        }
        self.nmt_state = NMT_STATE_PREOP
        self.node.add_read_callback(self._read)
        self.node.add_write_callback(self._write)
        self.network = None

    def attach(self, bus) -> None:
        """Use `bus` for SDO responses (no canopen Notifier thread: the bench feeds frames in)."""
        import canopen

        self.network = canopen.Network(bus)
        self.node.associate_network(self.network)
        # NMT is handled by the bench; keep canopen's NMT slave out of it
        self.network.unsubscribe(0, self.node.nmt.on_command)

    def on_sdo(self, can_id: int, data, timestamp: float = 0.0) -> None:
        self.network.notify(can_id, data, timestamp)

    # -- SDO callbacks -------------------------------------------------------------------------------
    def _read(self, index, subindex, od):
        d = self.drive
        if index == 0x6041:
            return d.statusword(brake_released=not (self.live[0x2110] & 0x01))
        if index == 0x6061:
            return d.mode
        if index == 0x6060:
            return d.mode
        if index == 0x6040:
            return d.controlword
        if index == 0x603F:
            return d.error_code
        if index == 0x1001:
            return d.error_register
        if index == 0x6071:
            return int(round(d.target_torque / NM_PER_PERMILLE))
        if index == 0x60B2:
            return int(round(d.torque_offset / NM_PER_PERMILLE))
        if index == 0x60FF:
            return int(round(d.target_velocity / RAD_PER_INC))
        if index == 0x2100:
            return 1 if d.brake_release else 0
        if index == 0x6072:
            return int(round(d.max_torque / NM_PER_PERMILLE))
        if index == 0x2030:
            return self.params["watchdog_cycles"]
        if index == 0x2033:
            return int(self.params["counter_check"])
        if index == 0x1016 and subindex == 1:
            return self.params["heartbeat_consumer"]
        if index == 0x1017:
            return self.params["heartbeat_producer_ms"]
        if index == 0x2040:
            return d.csv_kp
        if index == 0x2041:
            return d.csv_ti
        if index in self.live:
            return self.live[index]
        return None

    def _write(self, index, subindex, od, data):
        value = od.decode_raw(data)
        d = self.drive
        if index == 0x6040:
            d.apply_controlword(int(value))
        elif index == 0x6060:
            if not d.set_mode(int(value)):
                raise self._abort(0x06090030)             # value range of parameter exceeded
        elif index == 0x6071:
            tq = int(value) * NM_PER_PERMILLE
            if abs(tq) > d.max_torque + 1e-9:
                raise self._abort(0x06090030)
            d.target_torque = tq
        elif index == 0x60B2:
            d.torque_offset = int(value) * NM_PER_PERMILLE
        elif index == 0x60FF:
            d.target_velocity = int(value) * RAD_PER_INC
        elif index == 0x2100:
            d.brake_release = bool(int(value) & 1)
        elif index == 0x6072:
            d.max_torque = int(value) * NM_PER_PERMILLE
        elif index == 0x2030:
            if not 1 <= int(value) <= 100:
                raise self._abort(0x06090030)
            self.params["watchdog_cycles"] = int(value)
        elif index == 0x2033:
            self.params["counter_check"] = bool(int(value))
        elif index == 0x1016 and subindex == 1:
            self.params["heartbeat_consumer"] = int(value)
        elif index == 0x1017:
            self.params["heartbeat_producer_ms"] = int(value)
        elif index == 0x2040:
            if not (math.isfinite(value) and value >= 0):
                raise self._abort(0x06090030)
            d.csv_kp = float(value)
        elif index == 0x2041:
            if not (value > 0):
                raise self._abort(0x06090030)
            d.csv_ti = float(value)
        elif index == 0x1006:
            raise self._abort(0x08000022)     # cannot be changed in the present device state
        elif index in self.live or index in (0x6041, 0x6061, 0x603F, 0x1001):
            raise self._abort(0x06010002)     # read only
