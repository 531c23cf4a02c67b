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
from __future__ import annotations

import json
import math
import sys
from dataclasses import replace
from pathlib import Path

from .buses import MULTICAST_MODES, make_bus
from .runners import HilConfig, _make_plant, demo_scenario, run_hil


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
    res.record.to_csv(Path(a.out) / "results.csv")
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
