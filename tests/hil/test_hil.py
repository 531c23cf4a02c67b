"""Motor controller in the loop over CAN (docs/hil.md).

* protocol: the DBC (cantools) and the EDS (canopen) describe the same frames; the fast frame codec
  equals cantools bit for bit; the CiA 402 state machine;
* lock-step over `virtual` reproduces the in-process co-simulation (plant FMU, in its own subprocess);
* a cross-process run over `udp_multicast` on loopback;
* fault injection: frame loss, delay, a dead controller, malformed / out-of-range / stale frames, lost
  heartbeat; every wait is bounded;
* a canopen BaseNode402 master takes the simulated drive to OPERATION ENABLED and runs a short move.

Runs that do not load an FMU use the in-process plant (the same Plant the FMU wraps) to stay fast.
"""
from __future__ import annotations

import heapq
import json
import math
import random
import subprocess
import sys
import threading
import time
import uuid
from pathlib import Path

import numpy as np
import pytest

from reeve_fmu.hil import protocol as P
from reeve_fmu.hil.bridge import Bridge, BridgeConfig, FaultSpec, HilError
from reeve_fmu.hil.buses import make_bus
from reeve_fmu.hil.drive402 import Drive402
from reeve_fmu.fmu.runner import run_in_subprocess
from reeve_fmu.hil.buses import ensure_multicast
from reeve_fmu.hil.runners import HilConfig, run_hil
from tests.support import ROOT
from tests.support.checks import check, check_min, check_png

ROUNDOFF = "round-off, which differs by platform"
EXACT = "exact here; round-off in general"

JOBS = str(ROOT / "tests" / "support" / "hil_jobs.py")

# a short trip: 0 m -> 1 m, one move (pre-torque from the demo's holding torque at the bottom landing)
SHORT = {"landing[1]": 0.0, "landing[2]": 1.0, "trip.moves": 1, "pretorque[1]": 522.5, "pretorque[2]": 522.5,
         "drive.level": 1}
PLANT = {"car.load": 1000.0}


def _run(tmp_path=None, **kw):
    cfg = {"plant": "in-process", "drive_values": SHORT, "plant_values": PLANT, "t_end": 3.0, "out": None,
           "lockstep_timeout": 0.3}
    cfg.update(kw)
    if tmp_path is not None and cfg.get("out") is None:
        cfg["out"] = str(tmp_path / "hil")
    return run_hil(HilConfig(**cfg), log=None)


# ------------------------------------------------------------------------------------------------
# protocol
# ------------------------------------------------------------------------------------------------
def test_dbc_and_eds_describe_the_same_frames():
    """COB-IDs, transmission types and PDO mappings of the EDS equal the DBC's message layouts."""
    import cantools

    db = cantools.database.load_file(str(P.DBC_PATH))
    od = P.load_eds()
    pdos = {  # DBC message -> (communication index, mapping index)
        "TorqueCmd": (0x1400, 0x1600), "VelocityCmd": (0x1401, 0x1601),
        "DriveStatus": (0x1800, 0x1A00), "DriveFeedback": (0x1801, 0x1A01), "PlantStatus": (0x1802, 0x1A02)}
    for name, (com, mapping) in pdos.items():
        msg = db.get_message_by_name(name)
        assert od[com][1].default == msg.frame_id, name
        every = od[com][2].default
        assert msg.cycle_time == every, (name, msg.cycle_time, every)   # 1 ms SYNC: every n-th SYNC = n ms
        entries = [od[mapping][i].default for i in range(1, od[mapping][0].default + 1)]
        # mapped objects, in order, with their bit lengths; 1-bit DBC flags share one mapped byte (0x2110)
        bits = 0
        sigs = sorted(msg.signals, key=lambda s: s.start)
        i = 0
        for e in entries:
            index, length = e >> 16, e & 0xFF
            var = od[index]
            assert len(var) == length, (name, hex(index))
            group = []
            while i < len(sigs) and sigs[i].start < bits + length:
                group.append(sigs[i])
                i += 1
            assert group and group[0].start == bits, (name, hex(index))
            assert group[-1].start + group[-1].length <= bits + length, (name, hex(index))
            assert group[0].is_signed == (var.data_type in (0x2, 0x3, 0x4)) or len(group) > 1, (name, hex(index))
            bits += length
        assert i == len(sigs) and bits == 8 * msg.length, name
    assert [s.name for s in db.get_message_by_name("DriveStatus").signals if 40 <= s.start < 48] == [
        "BrakeApplied", "BrakeEngaged", "WatchdogTrip", "HeartbeatLost", "PlantFault", "CommandRejected",
        "CommandMissing", "QuickStop"]                   # the 8 bits of 0x2110
    # units the DBC scales with are the EDS's
    assert od[0x6076].default == P.RATED_TORQUE * 1000
    assert od[0x608F][1].default == P.INC_PER_REV
    assert db.get_message_by_name("TorqueCmd").get_signal_by_name("TargetTorque").scale == P.NM_PER_PERMILLE
    assert db.get_message_by_name("DriveFeedback").get_signal_by_name("PositionActual").scale == P.RAD_PER_INC
    assert od[0x6502].default == 0x300            # CSV + CST
    assert od[0x1006].default == 1000             # SYNC period 1 ms


def test_frame_codec_equals_cantools():
    import cantools

    db = cantools.database.load_file(str(P.DBC_PATH))
    proto = P.protocol()
    rng = random.Random(7)
    for msg in db.messages:
        codec = proto.codecs[msg.name]
        for _ in range(200):
            vals = {}
            for s in msg.signals:
                lo, hi = codec.raw_limits(s.name)
                vals[s.name] = rng.randint(lo, hi) * s.scale + s.offset
            data = codec.encode([vals[n] for n in codec.names])
            assert data == msg.encode(vals, strict=True), msg.name
            assert codec.decode(data) == [msg.decode(data, decode_choices=False)[n] for n in codec.names]
    tc = proto.TorqueCmd
    with pytest.raises(P.CodecError):
        tc.encode([15, 18100.0, 10, 1, 1])                      # beyond the DBC (int16) range
    with pytest.raises(P.CodecError):
        tc.decode_raw(b"\x00" * 6)                              # wrong length


def test_cia402_state_machine():
    d = Drive402()
    assert d.state == P.S_SWITCH_ON_DISABLED
    assert P.state_from_statusword(d.statusword()) == P.S_SWITCH_ON_DISABLED
    for cw, state in ((P.CW_SWITCH_ON, P.S_SWITCH_ON_DISABLED),        # no transition from SOD
                      (P.CW_SHUTDOWN, P.S_READY_TO_SWITCH_ON), (P.CW_SWITCH_ON, P.S_SWITCHED_ON),
                      (P.CW_ENABLE_OPERATION, P.S_OPERATION_ENABLED)):
        d.apply_controlword(cw)
        assert d.state == state and P.state_from_statusword(d.statusword()) == state
    d.target_torque, d.brake_release = 300.0, True
    assert d.actuation(0.0, 1e-3) == (300.0, 1.0)
    d.apply_controlword(P.CW_QUICK_STOP)                                # 11: torque off, brake applied
    assert d.state == P.S_QUICK_STOP_ACTIVE and d.actuation(0.0, 1e-3) == (0.0, 0.0)
    assert d.statusword() & 0x6F == 0x07
    d.apply_controlword(P.CW_ENABLE_OPERATION)                          # 16
    assert d.state == P.S_OPERATION_ENABLED
    assert d.fault(P.ERR_RPDO_TIMEOUT) and d.state == P.S_FAULT_REACTION_ACTIVE
    assert d.actuation(5.0, 1e-3) == (0.0, 0.0)
    d.at_sync()
    assert d.state == P.S_FAULT and d.statusword() & 0x4F == 0x08 and d.error_register & 0x10
    d.apply_controlword(P.CW_ENABLE_OPERATION)                          # ignored in FAULT
    assert d.state == P.S_FAULT
    d.apply_controlword(P.CW_FAULT_RESET)                               # 15: rising edge of bit 7
    assert d.state == P.S_SWITCH_ON_DISABLED and d.error_code == 0
    # CSV: the drive's speed PI with the torque offset as feed-forward, limited to the max torque
    d.apply_controlword(P.CW_SHUTDOWN), d.apply_controlword(P.CW_SWITCH_ON), d.apply_controlword(P.CW_ENABLE_OPERATION)
    assert d.set_mode(P.MODE_CSV) and not d.set_mode(1)
    d.target_velocity, d.torque_offset = 0.5, 100.0
    tq, _ = d.actuation(0.0, 1e-3)
    check('tq - (970.0 * 0.5 + 100.0)', tq - (970.0 * 0.5 + 100.0), 1e-12 * np.max(np.abs((970.0 * 0.5 + 100.0))), reason=EXACT)
    d.target_velocity = 50.0
    assert d.actuation(0.0, 1e-3)[0] == pytest.approx(d.max_torque)
    d.apply_controlword(P.CW_DISABLE_VOLTAGE)                           # 9
    assert d.state == P.S_SWITCH_ON_DISABLED


def test_inject_parsing():
    f = FaultSpec.parse(["loss=0.1@2", "delay=3", "controller-dies-at=4.5", "seed=3"])
    assert (f.loss, f.loss_from, f.delay_ms, f.controller_dies_at, f.seed) == (0.1, 2.0, 3.0, 4.5, 3)
    for bad in ("loss=2", "loss", "delay=-1", "bogus=1", "controller-dies-at=1@2"):
        with pytest.raises(ValueError):
            FaultSpec.parse([bad])


# ------------------------------------------------------------------------------------------------
# lock-step reproduces the in-process co-simulation
# ------------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def plant_fmu(tmp_path_factory):
    dest = tmp_path_factory.mktemp("hil_fmus")
    p = subprocess.run([sys.executable, "-m", "reeve_fmu.cli", "build", "--dest", str(dest)], cwd=ROOT,
                       capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stdout + p.stderr
    return str(dest / "ReevingPlant.fmu")


def test_lockstep_virtual_fmu_reproduces_inprocess_cosimulation(plant_fmu, tmp_path):
    """The plant FMU (fmpy, own subprocess) behind the bench, the ElectricDrive behind the bus: a full
    1 m move equals the in-process Plant + ElectricDrive run with the same step, one-cycle transport
    delay and CAN quantization exactly, and the demo's Gauss-Seidel coupling within 1 mm."""
    out = tmp_path / "hil"
    r = run_in_subprocess(f"{JOBS}:hil_run", {
        "plant": "fmu", "fmu_path": plant_fmu, "drive_values": SHORT, "plant_values": PLANT, "t_end": 5.5,
        "out": str(out)}, timeout=600)
    s = r["summary"]
    assert s["plant"]["kind"] == "fmu" and s["mode"] == "lock-step" and s["steps"] == 5500
    assert s["frames_rejected"] == 0 and s["watchdog_trips"] == 0 and s["lockstep_timeouts"] == 0
    assert s["commands_valid"] == 5499 and s["final_state"] == "OPERATION ENABLED"
    assert s["reference"]["max_abs_diff_car_position"] == 0.0
    assert s["reference"]["max_abs_diff_motor_speed"] == 0.0
    check('s["vs_demo_scheme"]["max_abs_diff_car_position"]', s["vs_demo_scheme"]["max_abs_diff_car_position"], 1e-4)
    x = np.asarray(r["columns"]["car.position"])
    check('x[-1] - 1.0', x[-1] - 1.0, 5e-4)  # stopped at the landing
    check('np.max(x) - 1.0', np.max(x) - 1.0, 1e-3)  # overshoot
    assert (out / "summary.json").is_file() and (out / "timing.csv").is_file()
    assert json.loads((out / "summary.json").read_text(encoding="utf-8"))["steps"] == 5500


def test_lockstep_is_deterministic_and_realtime_reports_timing(tmp_path):
    a = _run(t_end=1.5)
    b = _run(t_end=1.5)
    assert a["reference"]["max_abs_diff_car_position"] == 0.0 == b["reference"]["max_abs_diff_car_position"]
    r = _run(tmp_path, t_end=1.5, realtime=True)
    assert r["mode"] == "real-time" and r["steps"] == 1500
    assert r["wall_s"] >= 1.5 - 1e-3                               # paced by the wall clock
    assert 0 <= r["deadline_misses"] <= 1500
    assert r["controller_stats"]["operation_enabled_at"] is not None
    # the reported percentiles are those of the per-cycle log (timing.csv, written with 10 digits); the
    # figures themselves are machine-dependent and measured in benchmarks/hil_lockstep.py
    cols = np.genfromtxt(tmp_path / "hil" / "timing.csv", delimiter=",", names=True)
    assert len(cols) == 1500
    for col, key in (("step_time_us", "step_time"), ("sync_late_us", "sync_jitter")):
        x = cols[col]
        p50, p99 = np.percentile(x, 50), np.percentile(x, 99)
        check(f"{key} p50: summary - timing.csv", r[f"{key}_p50_us"] / p50 - 1, 1e-8, reason="the CSV's 10 significant digits: the difference depends on the run's timings")
        check(f"{key} p99: summary - timing.csv", r[f"{key}_p99_us"] / p99 - 1, 1e-8, reason="the CSV's 10 significant digits: the difference depends on the run's timings")
        check(f"{key} max: summary - timing.csv", r[f"{key}_max_us"] / np.max(x) - 1, 1e-8, reason="the CSV's 10 significant digits: the difference depends on the run's timings")
        assert r[f"{key}_p50_us"] <= r[f"{key}_p99_us"] <= r[f"{key}_max_us"]
    assert np.all(cols["step_time_us"] > 0.0)        # each cycle's work takes time
    assert np.all(cols["sync_late_us"] >= 0.0)       # a SYNC is never sent before its time


# ------------------------------------------------------------------------------------------------
# cross-process over udp_multicast
# ------------------------------------------------------------------------------------------------
def test_udp_multicast_cross_process_lockstep():
    ok, why = ensure_multicast()
    if not ok:
        pytest.skip(f"no IPv4 multicast on this host: {why}")
    s = _run(bus="udp_multicast", t_end=2.0)
    assert s["controller_stats"]["exit_code"] == 0 and s["controller_stats"]["pid"] > 0
    assert s["controller_stats"]["stopped"] == "done"
    assert s["frames_rejected"] == 0 and s["watchdog_trips"] == 0
    # same trajectory as the in-process reference: lock-step does not depend on the transport
    assert s["reference"]["max_abs_diff_car_position"] == 0.0
    assert s["car_travel_max_m"] > 0.1


# ------------------------------------------------------------------------------------------------
# fault injection and safety
# ------------------------------------------------------------------------------------------------
def test_frame_loss_holds_the_setpoint_then_trips_the_watchdog(tmp_path):
    from reeve_fmu.hil.runners import reference_run
    from reeve_fmu.core.results import read_csv

    light = _run(tmp_path, inject=["loss=0.02", "seed=3"])
    check_min("frames lost at p = 0.02", light["frames_injected"]["lost"], 20)
    assert light["commands_missing"] > 0 and light["watchdog_trips"] == 0 and light["fault"] is None
    # single lost commands are bridged by holding the last set-point: the trip barely changes
    x = read_csv(tmp_path / "hil" / "results.csv")["car.position"]
    ref = reference_run(3000, drive_values=SHORT, plant_values=PLANT)["car.position"]
    assert np.max(np.abs(x - ref)) > 0.0                                # the losses do change the run
    check("car position with 2 % of frames lost - without [m]", x - ref, 3e-6)
    heavy = _run(inject=["loss=0.6@2.0"], t_end=3.0)
    assert heavy["watchdog_trips"] == 1 and heavy["fault"]["code"] == "0x8250"
    # three missing commands at the earliest: SYNC 2003
    check_min("watchdog trip after the losses start [s]", heavy["brake_engaged_at"] - 2.0, 0.003 - 1e-9)
    check("watchdog trip after the losses start [s]", heavy["brake_engaged_at"] - 2.0, 0.05,
          reason="the trip waits for three losses in a row at p = 0.6, a random wait (seed-dependent)")
    assert heavy["brake_closed_at"] > heavy["brake_engaged_at"]
    assert heavy["machine_stopped_at"] is not None and heavy["final_state"] == "FAULT"
    assert heavy["controller_stats"]["fault_seen_at"] is not None


def test_delay_shorter_than_a_cycle_is_harmless_longer_is_stale_and_trips():
    short = _run(inject=["delay=0.5"], t_end=1.5)
    assert short["frames_rejected"] == 0 and short["watchdog_trips"] == 0
    long = _run(inject=["delay=2@2.0"])
    assert long["frames_rejected_detail"]["stale"] > 0
    assert long["watchdog_trips"] == 1
    # the last fresh command belongs to cycle 1999; cycles 2000..2002 bring none: trip at SYNC 2003
    check('long["brake_engaged_at"] - 2.003', long["brake_engaged_at"] - 2.003, 1e-9, reason=EXACT)
    assert long["machine_stopped_at"] is not None


def test_dead_controller_safe_stop_and_bounded_waits():
    s = _run(inject=["controller-dies-at=2.0"], t_end=4.0, stop_when_safe=True)
    assert s["controller_stats"]["died_at"] == pytest.approx(2.0)
    assert s["watchdog_trips"] == 1 and s["fault"]["reason"].startswith("command watchdog")
    check('s["brake_engaged_at"] - 2.003', s["brake_engaged_at"] - 2.003, 1e-9, reason=EXACT)  # 3 missing SYNC periods at 1 ms
    check_min("car speed at the fault [m/s] (it was moving)", s["car_speed_at_fault_m_s"], 0.3)
    # the brake stops it (its deceleration is tested against the closed form in tests/components/test_brake.py)
    check("machine stopped after the trip [s]", s["machine_stopped_at"] - s["brake_engaged_at"], 0.3)
    check("stop distance [m]", s["stop_distance_m"], 0.1)
    assert s["lockstep_timeouts"] == 3                                  # then the bench stops waiting
    # nobody starts the drive: the bench gives up after start_timeout (instead of waiting forever)
    with pytest.raises(HilError, match="no controller started"):
        _run(controller="external", start_timeout=1.0, t_end=1.0)


def test_corrupt_frames_are_malformed_and_many_trip_the_watchdog():
    """corrupt=P truncates frames by one byte: each corrupted command is rejected as malformed and the
    cycle counts as missing (the last set-point is held); all commands corrupt from 1.0 s: no fresh
    command at SYNC 1001..1003, so the watchdog trips at SYNC 1003 (1.003 s) exactly."""
    light = _run(inject=["corrupt=0.02", "seed=3"], t_end=2.0)
    rej = light["frames_rejected_detail"]
    check_min("frames corrupted at p = 0.02 (RPDOs + heartbeat)", light["frames_injected"]["corrupted"], 20)
    assert rej["malformed"] == light["commands_missing"] > 20 and rej["stale"] == 0
    assert light["watchdog_trips"] == 0 and light["fault"] is None
    heavy = _run(inject=["corrupt=1.0@1.0"], t_end=2.0)
    assert heavy["frames_rejected_detail"]["malformed"] == 1000         # every command from 1.0 s on
    assert heavy["watchdog_trips"] == 1 and heavy["final_state"] == "FAULT"
    check('heavy["brake_engaged_at"] - 1.003', heavy["brake_engaged_at"] - 1.003, 1e-12, reason=ROUNDOFF)


def test_realtime_late_commands_are_stale_and_trip_the_watchdog():
    """Real time: from 1.0 s every controller frame is held 5 ms of wall time, so each command arrives
    after its cycle has ended, carries an old counter and is rejected as stale; three SYNC periods
    without a fresh command trip the watchdog (brake applied, fault 0x8250)."""
    r = _run(realtime=True, inject=["delay=5@1.0"], t_end=2.0)
    assert r["mode"] == "real-time"
    assert r["watchdog_trips"] == 1 and r["fault"]["code"] == "0x8250"
    assert r["fault"]["reason"].startswith("command watchdog")
    assert r["final_state"] == "FAULT"
    if r["brake_engaged_at"] < 1.0:
        # a machine that misses 1 ms deadlines of wall time before the injection (heavy load) still ends
        # in the same safe state by the same watchdog, from the missed cycles themselves (checked above);
        # what follows needs wall-clock deadlines met, and is tested on a simulated clock as well
        # (test_realtime_watchdog_on_a_simulated_clock)
        assert r["deadline_misses"] > 0
        pytest.skip(f"real time: this machine missed {r['deadline_misses']} deadlines of 1 ms and the watchdog "
                    f"tripped at {r['brake_engaged_at']:.3f} s, before the injected delay at 1.0 s")
    check_min("frames delayed", r["frames_injected"]["delayed"], 900)
    check_min("commands rejected as stale", r["frames_rejected_detail"]["stale"], 900)
    assert r["brake_engaged_at"] > 1.0
    check("watchdog trip after the delay starts [s] (3 SYNC periods, 3 ms, when on time)", r["brake_engaged_at"] - 1.0,
          0.01)


class SimNet:
    """A CAN network on a simulated wall clock: real time made exact. Each party (a SimBus) runs in its own
    thread; simulated time stands still while any party is busy (outside recv) and, when all wait, jumps to
    the next frame arrival or recv deadline. A frame arrives `latency` after it is sent, so a run's timing
    does not depend on the machine: an injected 5 ms delay is 5 ms, and no deadline is ever missed."""

    def __init__(self, latency=1e-4):
        self.now = 0.0
        self.latency = latency
        self.cv = threading.Condition()
        self.buses = []
        self.seq = 0

    def clock(self):
        return self.now

    def bus(self):
        b = SimBus(self)
        with self.cv:
            self.buses.append(b)
        return b


class SimBus:
    def __init__(self, net):
        self.net, self.inbox, self.waiting_until, self.open = net, [], None, True

    def send(self, msg, timeout=None):
        import can

        net = self.net
        with net.cv:
            t = net.now + net.latency
            for b in net.buses:
                if b is not self and b.open:
                    net.seq += 1
                    heapq.heappush(b.inbox, (t, net.seq, can.Message(
                        arbitration_id=msg.arbitration_id, data=bytes(msg.data), is_extended_id=False, timestamp=t)))
            net.cv.notify_all()

    def recv(self, timeout=None):
        net = self.net
        with net.cv:
            self.waiting_until = net.now + (math.inf if timeout is None else timeout)
            try:
                while True:
                    if self.inbox and self.inbox[0][0] <= net.now:
                        return heapq.heappop(self.inbox)[2]
                    if net.now >= self.waiting_until:
                        return None
                    live = [b for b in net.buses if b.open]
                    if all(b.waiting_until is not None for b in live):      # everybody waits: next event
                        nxt = min([b.inbox[0][0] for b in live if b.inbox] + [b.waiting_until for b in live])
                        if not math.isfinite(nxt):
                            raise RuntimeError("SimNet: every party waits forever")
                        if nxt > net.now:
                            net.now = nxt
                            net.cv.notify_all()
                            continue
                    # another party has something due now (or is busy): let it run
                    if not net.cv.wait(600.0):
                        raise RuntimeError("SimNet: a party stayed busy for 600 s of wall time")
            finally:
                self.waiting_until = None

    def shutdown(self):
        with self.net.cv:
            self.open = False
            self.net.cv.notify_all()


def _simulated_realtime_run(dt, inject, t_end):
    """Bench (real-time mode, in-process plant) and the built-in controller on a SimNet."""
    from reeve_fmu.hil.bridge import Injector
    from reeve_fmu.hil.controller import BuiltinController, ControllerConfig
    from reeve_fmu.hil.plants import InProcessPlant, make_default_plant

    n = int(round(t_end / dt))
    net = SimNet()
    bus, cbus = net.bus(), net.bus()
    inj = Injector(FaultSpec.parse(inject), dt, lockstep=False)
    bridge = Bridge(bus, InProcessPlant(make_default_plant(params=PLANT)),
                    BridgeConfig(dt=dt, realtime=True, rt_priority=0, start_timeout=30.0), inj, clock=net.clock)
    ctl = BuiltinController(cbus, ControllerConfig(dt=dt, n_steps=n, drive_values=SHORT))
    out = {}
    th = threading.Thread(target=lambda: out.setdefault("ctl", ctl.run()), daemon=True)
    th.start()
    try:
        res = bridge.run(n)
    finally:
        bus.shutdown()
        th.join(30)
        cbus.shutdown()
    return res, out["ctl"], inj


@pytest.mark.parametrize("dt", [1e-3, 5e-3])
def test_realtime_watchdog_on_a_simulated_clock(dt):
    """Real-time mode on a simulated wall clock (SimNet): from 1.0 s every controller frame is held 5 ms, so
    each command arrives 5 ms (1 or 5 SYNC periods) after its SYNC, carries that SYNC's counter and is
    stale; SYNCs k0+1, k0+2, k0+3 find no fresh command and the watchdog trips at SYNC k0+3 exactly
    (k0 = the first SYNC at 1.0 s; CiA 402 watchdog 0x2030 = 3). Every delayed command that is released
    before the end is counted as stale; the controller heartbeat (every 10 ms, consumer 50 ms) is only late,
    not lost. At 5 ms SYNC the heartbeat used to be every 10th SYNC = 50 ms = the consumer time, and the
    5 ms delay tripped the heartbeat consumer at SYNC k0+1 instead."""
    res, ctl, inj = _simulated_realtime_run(dt, ["delay=5@1.0"], t_end=1.1)
    st = res.stats
    n, k0, d = st.steps, int(round(1.0 / dt)), int(round(5e-3 / dt))
    assert n == int(round(1.1 / dt)) and st.deadline_misses == 0 and np.all(st.sync_jitter == 0.0)
    assert ctl.operation_enabled_at is not None and ctl.operation_enabled_at < 0.1
    # the answers to SYNC 0..k0-1 are applied at SYNC 1..k0; frames are read in the wait that ends a cycle,
    # so the answers to SYNC k0..n-2 are delayed (that to SYNC n-1 is never read) and those released before
    # the last wait (sent at SYNC k0..n-2-d) are rejected as stale
    assert st.commands_valid == k0
    assert st.watchdog_trips == 1 and st.heartbeat_faults == 0 and st.fault_code == P.ERR_RPDO_TIMEOUT
    assert st.fault_at == st.brake_engaged_at == (k0 + 3) * dt
    assert st.rejected_stale == n - 1 - k0 - d and st.frames_rejected == st.rejected_stale
    hb_every = max(1, round(10e-3 / dt))
    assert inj.delayed == (n - 1 - k0) + len(range(k0, n - 1, hb_every))     # RPDO1s and heartbeats
    assert st.brake_closed_at is not None and st.brake_closed_at > st.brake_engaged_at


def _scripted_bench(script, n=40):
    """The bench (in-process plant) against a scripted controller thread: script(k, counter, send)."""
    from reeve_fmu.hil.plants import InProcessPlant

    ch = "hil_script_" + uuid.uuid4().hex[:6]
    bus = make_bus("virtual", ch)
    cbus = make_bus("virtual", ch)
    bridge = Bridge(bus, InProcessPlant(), BridgeConfig(lockstep_timeout=0.3, start_timeout=5.0))
    import can

    def send(cob, data):
        cbus.send(can.Message(arbitration_id=cob, data=bytes(data), is_extended_id=False))

    def controller():
        deadline = time.time() + 20
        while time.time() < deadline:
            m = cbus.recv(0.5)
            if m is not None and m.arbitration_id == P.COB_HB_DRIVE:
                break
        send(P.COB_NMT, [P.NMT_START, 1])
        k, c = -1, 0
        while time.time() < deadline:
            m = cbus.recv(1.0)
            if m is None:
                return
            if m.arbitration_id == P.COB_SYNC:
                k, c = k + 1, m.data[0]
            elif m.arbitration_id == P.COB_TPDO2:
                script(k, c, send)
                if k >= n - 1:
                    return

    bridge.warm_up()                     # JIT before the scripted controller's clock starts
    th = threading.Thread(target=controller, daemon=True)
    th.start()
    try:
        res = bridge.run(n)
    finally:
        th.join(10)
        bus.shutdown()
        cbus.shutdown()
    return res


def test_malformed_out_of_range_and_stale_frames_are_rejected_and_counted():
    tc = P.protocol().TorqueCmd
    state = {"cw": P.CW_SHUTDOWN}

    def script(k, c, send):
        cw = [P.CW_SHUTDOWN, P.CW_SWITCH_ON][min(k, 1)] if k < 2 else P.CW_ENABLE_OPERATION
        good = tc.encode([cw, 100.0, P.MODE_CST, 1, c])
        if k == 10:
            send(P.COB_RPDO1, good[:5])                                  # malformed: 5 of 7 bytes
        elif k == 11:
            raw = bytearray(good)
            raw[2:4] = (2000).to_bytes(2, "little", signed=True)         # 1100 N m > 0x6072 max torque
            send(P.COB_RPDO1, raw)
        elif k == 12:
            send(P.COB_RPDO1, tc.encode([cw, 100.0, 1, 0, c], strict=False))   # unsupported mode 1
        elif k == 13:
            send(P.COB_RPDO1, tc.encode([cw, 100.0, P.MODE_CST, 0, (c - 2) % 240 + 1]))   # stale counter
            send(P.COB_RPDO1, good)                                       # then the fresh one
        elif k == 14:
            send(P.COB_HB_CONTROLLER, [5, 7])
            send(P.COB_HB_CONTROLLER, [5, 7])                             # repeated heartbeat counter
            send(P.COB_RPDO1, good)
        else:
            send(P.COB_RPDO1, good)
        state["cw"] = cw

    res = _scripted_bench(script)
    st = res.stats
    assert st.rejected_malformed == 1 and st.rejected_out_of_range == 2 and st.rejected_stale == 2
    assert st.frames_rejected == 5
    assert st.commands_missing == 3 and st.watchdog_trips == 1       # cycles 10-12 brought no valid command
    assert st.fault_code == P.ERR_RPDO_TIMEOUT and st.fault_at == pytest.approx(0.013, abs=1e-9)
    flags = res.column("hil.flags")
    assert int(flags[11]) & 32 and int(flags[12]) & 64                 # CommandRejected / CommandMissing bits
    assert np.allclose(res.column("hil.torque")[4:13], 182 * 0.55, rtol=0, atol=1e-12)   # 182 per mille
    assert np.all(res.column("hil.brake_command")[4:13] == 1.0)
    assert np.all(res.column("hil.torque")[13:] == 0.0)                # FAULT: torque off ...
    assert np.all(res.column("hil.brake_command")[13:] == 0.0)         # ... and the brake applied


def test_lost_controller_heartbeat_faults_the_drive():
    tc = P.protocol().TorqueCmd

    def script(k, c, send):
        if k == 0:   # heartbeat consumer 0x1016:01 = node 0x10, 20 ms (expedited SDO download)
            send(P.COB_SDO_RX, bytes([0x23, 0x16, 0x10, 0x01]) + ((0x10 << 16) | 20).to_bytes(4, "little"))
        cw = (P.CW_SHUTDOWN, P.CW_SWITCH_ON)[k] if k < 2 else P.CW_ENABLE_OPERATION
        if k < 10 and k % 5 == 0:
            send(P.COB_HB_CONTROLLER, [5, k // 5])                        # heartbeats stop after 5 ms
        send(P.COB_RPDO1, tc.encode([cw, 0.0, P.MODE_CST, 0, c]))

    res = _scripted_bench(script, n=60)
    st = res.stats
    assert st.heartbeat_faults == 1 and st.fault_code == P.ERR_HEARTBEAT
    check('st.fault_at - 0.026', st.fault_at - 0.026, 1e-12, reason=ROUNDOFF)  # last heartbeat at 5 ms + 20 ms
    assert st.watchdog_trips == 0 and st.sdo_requests == 1


# ------------------------------------------------------------------------------------------------
# a canopen BaseNode402 master drives the simulated drive
# ------------------------------------------------------------------------------------------------
def test_canopen_basenode402_enables_the_drive_and_runs_a_short_move():
    import canopen
    from canopen.profiles.p402 import BaseNode402

    from reeve_fmu.hil.plants import InProcessPlant

    ch = "hil_402_" + uuid.uuid4().hex[:6]
    bus = make_bus("virtual", ch)
    bridge = Bridge(bus, InProcessPlant(), BridgeConfig(lockstep_timeout=0.5, start_timeout=30.0))
    bridge.warm_up()
    stop = threading.Event()
    out = {}
    th = threading.Thread(target=lambda: out.setdefault("res", bridge.run(120_000, stop=stop)), daemon=True)
    th.start()
    net = canopen.Network()
    net.connect(interface="virtual", channel=ch)
    try:
        node = BaseNode402(1, str(P.EDS_PATH))
        net.add_node(node)
        node.nmt.state = "PRE-OPERATIONAL"
        node.setup_402_state_machine(read_pdos=True)        # PDO configuration uploaded over SDO
        assert {0x6040, 0x6060, 0x6071, 0x60FF} <= set(node.rpdo_pointers)
        assert {0x6041, 0x6061, 0x6064, 0x606C} <= set(node.tpdo_values)
        assert node.sdo[0x6502].raw == 0x300
        ctl = {"c": 0, "k": -1, "start": None, "done": False, "vmax": 5.0}

        def on_sync(can_id, data, ts):
            ctl["c"], ctl["k"] = data[0], ctl["k"] + 1

        def on_tpdo2(can_id, data, ts):   # the master's cyclic task: RPDO2 (velocity), then RPDO1
            if ctl["start"] is not None:
                tau = (ctl["k"] - ctl["start"]) * 1e-3
                v = ctl["vmax"] * (min(1.0, tau / 0.2) if tau < 0.5 else max(0.0, 1.0 - (tau - 0.5) / 0.2))
                node.rpdo[2]["Target velocity"].raw = round(v / P.RAD_PER_INC)
                node.rpdo[2]["Torque offset"].raw = round(522.5 / P.NM_PER_PERMILLE)   # load-weighing feed-forward
                ctl["done"] = tau > 0.9
            node.rpdo[1]["Command counter"].raw = ctl["c"]
            node.rpdo[2].transmit()
            node.rpdo[1].transmit()

        net.subscribe(P.COB_SYNC, on_sync)
        net.subscribe(P.COB_TPDO2, on_tpdo2)
        node.nmt.state = "OPERATIONAL"
        node.op_mode = "CYCLIC SYNCHRONOUS VELOCITY"
        assert node.op_mode == "CYCLIC SYNCHRONOUS VELOCITY"
        node.state = "OPERATION ENABLED"
        assert node.state == "OPERATION ENABLED"
        x0 = node.tpdo_values[0x6064]
        node.rpdo[1]["Brake command"].raw = 1
        ctl["start"] = ctl["k"]
        deadline = time.time() + 60
        while not ctl["done"] and time.time() < deadline:
            time.sleep(0.01)
        assert ctl["done"]
        node.rpdo[1]["Brake command"].raw = 0
        node.check_statusword()
        moved = (node.tpdo_values[0x6064] - x0) * P.RAD_PER_INC
        # the profile integrates to 2.5 rad; the master's thread sends it in wall-clock time
        check_min("motor travel / 2.5 rad", moved / 2.5, 0.6)
        check("motor travel / 2.5 rad", moved / 2.5, 1.2)
        node.state = "SWITCH ON DISABLED"
        assert node.state == "SWITCH ON DISABLED"
    finally:
        stop.set()
        th.join(30)
        net.disconnect()
        bus.shutdown()
    st = out["res"].stats
    assert st.frames_rejected == 0 and st.watchdog_trips == 0 and st.sdo_requests > 10
    assert st.commands_valid == st.steps - 1


def test_controller_as_sync_producer_and_sync_loss():
    """--sync controller: each SYNC from the controller advances the plant one period; when the SYNCs
    stop, the drive faults (EMCY 0x8100), applies the brake and the bench finishes on its own clock."""
    import can

    from reeve_fmu.hil.plants import InProcessPlant

    ch = "hil_extsync_" + uuid.uuid4().hex[:6]
    bus, cbus = make_bus("virtual", ch), make_bus("virtual", ch)
    bridge = Bridge(bus, InProcessPlant(), BridgeConfig(sync_source="controller", sync_timeout=0.2,
                                                        start_timeout=5.0))
    tc = P.protocol().TorqueCmd
    seen = {"emcy": None, "tpdo1": 0}

    def send(cob, data):
        cbus.send(can.Message(arbitration_id=cob, data=bytes(data), is_extended_id=False))

    def controller():
        deadline = time.time() + 20
        while time.time() < deadline and (m := cbus.recv(0.5)) is not None:
            if m.arbitration_id == P.COB_HB_DRIVE:
                break
        send(P.COB_NMT, [P.NMT_START, 1])
        for k in range(30):                            # 30 SYNC cycles, then silence
            c = P.sync_counter(k)
            send(P.COB_SYNC, [c])
            while time.time() < deadline:
                m = cbus.recv(1.0)
                if m is not None and m.arbitration_id == P.COB_TPDO2:
                    break
            cw = (P.CW_SHUTDOWN, P.CW_SWITCH_ON)[k] if k < 2 else P.CW_ENABLE_OPERATION
            send(P.COB_RPDO1, tc.encode([cw, 522.5, P.MODE_CST, 1, c]))
        while time.time() < deadline and (m := cbus.recv(0.5)) is not None:
            if m.arbitration_id == P.COB_EMCY:
                seen["emcy"] = bytes(m.data)

    bridge.warm_up()
    th = threading.Thread(target=controller, daemon=True)
    th.start()
    try:
        res = bridge.run(100)
    finally:
        th.join(10)
        bus.shutdown()
        cbus.shutdown()
    st = res.stats
    assert st.steps == 100 and st.frames_rejected == 0
    assert st.commands_valid == 30                                       # one per controller SYNC
    assert st.fault_code == P.ERR_SYNC and st.fault_at == pytest.approx(0.030, abs=1e-9)
    check('st.brake_engaged_at - 0.030', st.brake_engaged_at - 0.030, 1e-9, reason=EXACT)
    assert np.all(res.column("hil.state")[:3] != P.S_OPERATION_ENABLED)
    assert np.all(res.column("hil.state")[3:30] == P.S_OPERATION_ENABLED)
    assert np.all(res.column("hil.brake_command")[31:] == 0.0)
    assert seen["emcy"] is not None and int.from_bytes(seen["emcy"][:2], "little") == P.ERR_SYNC


# ------------------------------------------------------------------------------------------------
# entry points
# ------------------------------------------------------------------------------------------------
def test_reeve_fmu_hil_command(plant_fmu, tmp_path, monkeypatch, capsys):
    """`reeve-fmu hil` (plant FMU, built-in controller, virtual bus): 0.8 s lock-step, exit 0, the
    summary and results written, the bench equal to the in-process reference of the same scheme."""
    from reeve_fmu.cli import main
    monkeypatch.setenv("REEVE_FMU_FMUS", str(Path(plant_fmu).parent))
    out = tmp_path / "hil"
    assert main(["hil", "--t-end", "0.8", "--out", str(out)]) == 0
    s = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    assert s["steps"] == 800 and s["mode"] == "lock-step" and s["plant"]["kind"] == "fmu"
    assert s["watchdog_trips"] == 0 and s["frames_rejected"] == 0
    assert s["reference"]["max_abs_diff_car_position"] == 0.0
    assert "results.csv" in capsys.readouterr().out


def test_hil_summary_report_and_console_carry_the_verdicts(tmp_path, capsys):
    """A 1 m trip on the in-process plant: summary.json, report.md (with the trip plots) and the console
    carry every verdict with value and limit. The checks use what the bench ran: the drive's default
    torque limit (1000 N m, not the one sized from the scene), its rated speed (the overspeed value is the
    record's peak car speed over 1.6 m/s), and the coupling monitor over the exchanged torque and speed
    (the bench is a 1 ms Jacobi coupling): stable through the stop and the brake drop, where the speed
    loop used to chatter on the brake's stick spring (peak 8.2 % of torque.max, FAIL) before the drive
    held its torque while the brake closes."""
    from reeve_fmu.hil.cli import _print_summary

    r = _run(tmp_path, t_end=5.5)
    vs = {v["check"]: v for v in r["verdicts"]}
    for name in ("stopping accuracy", "levelling band", "traction ratio during the trip", "co-simulation coupling",
                  "drive at its torque/power limit", "car speed / rated speed", "HIL drive fault (watchdog, "
                  "heartbeat, SYNC, plant)", "HIL frames rejected", "HIL lock-step timeouts"):
        assert name in vs, name
    assert all(v["status"] in ("PASS", "WARN", "FAIL") and isinstance(v["limit"], float) for v in vs.values())
    assert "torque.max 1000 N·m" in vs["drive at its torque/power limit"]["source"]
    check('vs["car speed / rated speed"]["value"] - (100 * r["car_speed_max_m_...', vs["car speed / rated speed"]["value"] - (100 * r["car_speed_max_m_s"] / 1.6), 1e-12 * np.max(np.abs((100 * r["car_speed_max_m_s"] / 1.6))), reason=EXACT)
    cp = vs["co-simulation coupling"]
    assert cp["status"] == "PASS" and r["coupling"]["coupling_stable"] and cp["limit"] == 1.0
    assert cp["value"] == pytest.approx(max(r["coupling"]["torque_chatter_max"] / 0.05,
                                            r["coupling"]["energy_residual_max_ratio"]), rel=1e-12)
    check('r["coupling"]["torque_chatter_max"]', r["coupling"]["torque_chatter_max"], 1.5e-3)
    assert vs["stopping accuracy"]["status"] == "PASS" and vs["HIL drive fault (watchdog, heartbeat, SYNC, plant)"]["status"] == "PASS"
    out = tmp_path / "hil"
    md = (out / "report.md").read_text(encoding="utf-8")
    assert md.count("| **") == len(vs) and f"Overall verdict: **{r['verdict']}**" in md
    for png in ("results.png", "traction.png", "motor.png", "levelling.png"):
        assert f"]({png})" in md
        check_png(out / png)
    assert json.loads((out / "summary.json").read_text(encoding="utf-8"))["verdicts"] == r["verdicts"]
    _print_summary(r, HilConfig(out=str(out)))
    printed = capsys.readouterr().out
    assert all(f"[{v['status']}] {c}: " in printed for c, v in vs.items())
    assert f"overall: {r['verdict']}" in printed and "report.md" in printed


def test_hil_drive_is_sized_from_the_scene_and_its_torque_limit_reaches_the_bench():
    """`hil` runs the demo's drive sized from the scene (torque and power limits, inertia, speed-loop gain),
    not the drive's 1000 N m / 20 kW defaults; the built-in controller writes the model's torque limit
    into the drive's 0x6072 (rounded up to whole per mille of 550 N m) and clamps its commands there: a
    pre-torque of 1050 N m with torque.max 1100 N m reaches the plant (a clamp at the default 1000 N m
    would hold it at 1000.45 N m) and no command is rejected."""
    from reeve_fmu.hil.controller import make_electric_drive, max_torque_permille
    from reeve_fmu.hil.runners import _with_defaults
    from reeve_fmu.studies.trip import sized_drive, trip_case

    cfg, _ = _with_defaults(HilConfig())
    sized = sized_drive(trip_case(None).scene)
    for k in ("torque.max", "torque.power_max", "control.Kp", "control.J_ff"):
        assert cfg.drive_values[k] == sized[k], k
    assert cfg.drive_values["torque.max"] != 1000.0 and cfg.drive_values["control.Kp"] != 970.0
    assert max_torque_permille(make_electric_drive({"torque.max": 1100.0})) == 2000      # 1100 / 0.55
    assert max_torque_permille(make_electric_drive({"torque.max": 1100.1})) == 2001
    dv = dict(SHORT, **{"torque.max": 1100.0, "pretorque[1]": 1050.0})
    r = _run(t_end=0.8, drive_values=dv)          # pre-torque ramp 0.5 .. 0.7 s with the brake applied
    assert r["frames_rejected"] == 0 and r["watchdog_trips"] == 0
    # to the ramp's last quantized steps (0.55 N m per unit)
    assert r["motor_torque_peak_Nm"] <= 1050.0 + 0.55
    check("peak motor torque - pre-torque 1050 N m", r["motor_torque_peak_Nm"] - 1050.0, 2 * 0.55)


def test_hil_coupling_check_flags_an_alternating_torque():
    """The coupling monitor on a bench record: a torque alternating by +-300 N m from cycle to cycle has a
    period-2 RMS of 300 N m, 30 % of the 1000 N m scale (limit 5 %): detected; a constant torque is not."""
    from reeve_fmu.hil.review import coupling_report

    n = 200
    t = np.arange(n) * 1e-3
    base = {"hil.brake_command": np.ones(n), "motor.speed": np.full(n, 10.0), "motor.angle": 10.0 * t}
    bad = coupling_report(t, dict(base, **{"hil.torque": 500.0 + 300.0 * (-1.0) ** np.arange(n)}), 1e-3, 1000.0)
    assert bad["coupling_stable"] is False
    assert "torque chatter" in {e["criterion"] for e in bad["instability_episodes"]}
    check('bad["torque_chatter_max"] / 0.3 - 1', bad["torque_chatter_max"] / 0.3 - 1, 1e-9, reason=EXACT)
    ok = coupling_report(t, dict(base, **{"hil.torque": np.full(n, 500.0)}), 1e-3, 1000.0)
    assert ok["coupling_stable"] is True


def test_hil_bench_entry_point_serves_a_controller(tmp_path, capsys):
    """`python -m reeve_fmu.hil bench` (here on python-can's virtual interface, in-process plant,
    lock-step) waits for the controller's NMT start, serves 500 SYNC cycles and writes results.csv."""
    import threading
    from reeve_fmu.hil.controller import BuiltinController, ControllerConfig
    from reeve_fmu.hil.cli import main as hil_main
    from reeve_fmu.core.results import read_csv

    ch = "hil_bench_" + uuid.uuid4().hex[:6]
    out = tmp_path / "bench"
    rc = {}
    bench = threading.Thread(target=lambda: rc.setdefault("bench", hil_main(
        ["bench", "--interface", "virtual", "--channel", ch, "--plant", "in-process", "--lockstep",
         "--t-end", "0.5", "--start-timeout", "30", "--out", str(out)])))
    bench.start()
    time.sleep(0.5)                                  # the bench is listening before the controller boots it
    cbus = make_bus("virtual", ch)
    try:
        st = BuiltinController(cbus, ControllerConfig(n_steps=500, drive_values=SHORT)).run()
    finally:
        cbus.shutdown()
    bench.join(60)
    assert not bench.is_alive() and rc["bench"] == 0
    printed = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert printed["steps"] == 500 and printed["watchdog_trips"] == 0 and printed["frames_rejected"] == 0
    assert len(read_csv(out / "results.csv")["time"]) == 501
    assert st.as_dict()["operation_enabled_at"] is not None
