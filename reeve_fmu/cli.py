"""Command line: reeve-fmu simulate | demo | build | sweep | bench | crane | hil.

Front ends import the layers below them; each subcommand's implementation lives in its own module and
is imported only when used, so `reeve-fmu simulate` does not load fmpy or python-can.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

PACKAGE_DIR = Path(__file__).resolve().parent




def cmd_simulate(args) -> int:
    from .core.model import build_model
    from .core.plausibility import initial_statics
    from .core.solver import Simulator, SolverError

    scene = _scene_with_sets(args.scene, getattr(args, "set", None))
    warnings = plausibility_warnings(scene)
    t_end = args.t_end if args.t_end is not None else scene.t_end
    dt = args.dt if args.dt is not None else scene.output_step
    for opt, v in (("--t-end", args.t_end), ("--dt", args.dt), ("--step", args.step)):
        if v is not None and not (0 < v < float("inf")):
            raise ValueError(f"{opt} must be a finite number > 0 [s], got {v:g}")
    out = Path(args.out)
    scene, chosen_step, res = _fidelity(args, scene, t_end, dt, out)
    reused = res is not None
    stop = None
    t0 = time.perf_counter()
    if res is None:    # (the fidelity selection's full-run check already ran the chosen configuration)
        step = chosen_step if chosen_step is not None else args.step
        sim = Simulator(build_model(scene), method=args.method, step=step)
        # an equilibrium with a compressed rope is no state to simulate from (exit 2, the rope named)
        st = initial_statics(sim)
        try:
            res = sim.run(t_end, dt, state=st)
        except SolverError as exc:
            if exc.result is None:      # nothing computed (e.g. the initial statics failed)
                raise
            res, stop = exc.result, exc
        warnings += sim.warnings
    wall = time.perf_counter() - t0
    cols = res.as_dict()
    time_ = cols.pop("time")
    from .studies.crane import crane_angles, hoist_convention
    convention = hoist_convention(scene, cols)
    crane_angles(scene, cols)                       # the crane FMU's swing and yaw angles, same names
    _write_run(out, scene, time_, cols, warnings, stop, wall if not reused else None, convention)
    _simulate_extras(args, scene, time_, cols, out)
    how = ("(the run of the fidelity full-run check)" if reused else
           f"in {wall:.2f} s (incl. statics and JIT load; {real_time(time_[-1] - time_[0], wall)})")
    print(f"{scene.name}: {len(time_)} samples to t = {time_[-1]:.3f} s {how} -> {out}/results.csv, "
          f"results.png, summary.json")
    if stop is not None:
        print(f"reeve-fmu simulate: run stopped by an event: {stop}; the results up to then are written",
              file=sys.stderr)
        return EXIT_EVENT
    return 0


def _scene_with_sets(path, items):
    """The scene file with --set overrides (scene keys, and the load of an elevator scene)."""
    from .studies.overrides import OverrideError, parse_sets, scene_with, split

    scene_sets, drive_sets, load = split(parse_sets(items))
    if drive_sets:
        raise OverrideError(f"--set {next(iter(drive_sets))}: drive parameters apply to demo and sweep; "
                            f"simulate runs the scene's own [drive]")
    scene, _ = scene_with(path, scene_sets)
    if load is not None:
        from .components.elevator import with_load
        scene = with_load(scene, load)
    return scene


def _simulate_extras(args, scene, time_, cols, out):
    """--output-dt / --parquet tables, and the checks of any scene run (slack rope, buffer contact,
    traction against EN 81-50): console, verdicts added to DIR/summary.json, DIR/report.md."""
    import json
    from .core.scene import scene_parameters
    from .studies import report
    from .studies.verdicts import explain, print_verdicts, scene_verdicts, worst

    if getattr(args, "output_dt", None) is not None or getattr(args, "parquet", False):
        report.write_tables(out, time_, cols, output_dt=getattr(args, "output_dt", None),
                            parquet=bool(getattr(args, "parquet", False)))
    vs = [v.as_dict() for v in scene_verdicts(scene, time_, cols)]
    p = out / "summary.json"
    summary = json.loads(p.read_text(encoding="utf-8")) if p.is_file() else {}
    summary.update({"verdict": worst(vs), "verdicts": vs, "findings": explain(vs)})
    report.write_summary(out, summary)
    report.write_report(out, f"Simulation: {scene.name}", {"scene file": scene.source, "model": scene.model,
                                                           "t_end_s": float(time_[-1]),
                                                           "motor sign": summary.get("motor_sign_convention", "")},
                        [], vs, ["results.png"] + (["crane.png"] if (out / "crane.png").is_file() else []),
                        command="reeve-fmu simulate",
                        parameters={"Scene (after --set)": scene_parameters(scene)})
    print_verdicts(vs)


def real_time(sim_seconds: float, wall: float) -> str:
    """'1364x real time', '2.5x real time', '0.11x real time'."""
    x = sim_seconds / wall if wall > 0 else float("inf")
    return f"{x:.0f}x real time" if x >= 10 else f"{x:.2g}x real time"


def plausibility_warnings(scene) -> list[str]:
    """Plausibility checks of a parsed scene (core/plausibility.py): raise for impossible values,
    print the warnings to stderr and return them."""
    from .core.plausibility import check_or_raise
    warnings = check_or_raise(scene)
    for w in warnings:
        print(f"warning: {w}", file=sys.stderr)
    return warnings


def _write_run(out, scene, time_, cols, warnings, stop, wall, convention=""):
    """results.csv, results.png (the event marked) and summary.json of a simulate run."""
    import json
    from .core.results import plot_overview, write_csv
    from .core.scene import scene_parameters
    from .studies.report import _json_default
    out.mkdir(parents=True, exist_ok=True)
    write_csv(out / "results.csv", time_, cols)
    event = None
    if stop is not None:
        msg = str(stop)
        event = {"time": stop.time, "cause": msg.split(": ", 1)[1].split(":")[0] if ": " in msg else msg,
                 "message": msg}
    plot_overview(out / "results.png", time_, cols, title=f"{scene.name} ({scene.model})",
                  event=None if event is None else (event["time"], event["cause"]))
    from .studies.crane import plot_crane_angles
    plot_crane_angles(out / "crane.png", scene, time_, cols)
    summary = {"scene": scene.name, "source": scene.source, "model": scene.model,
               "samples": int(len(time_)), "t_last": float(time_[-1]),
               "wall_seconds": wall, "warnings": list(warnings), "event": event,
               "exit_code": EXIT_EVENT if event else 0, "motor_sign_convention": convention,
               "parameters": {"scene": scene_parameters(scene)}}
    (out / "summary.json").write_text(json.dumps(summary, indent=2, default=_json_default) + "\n",
                                      encoding="utf-8")


def _fidelity(args, scene, t_end, dt, out):
    """Fidelity selection (docs/fidelity.md) when the scene has [accuracy] or --accuracy-* is given:
    print and write the report, return the configured scene, the chosen step and its full run (if the
    selection's full-run check made it)."""
    if args.no_fidelity:
        return scene, None, None
    from .studies.fidelity import accuracy_for, configure, select
    outputs = None
    if args.accuracy_outputs is not None:
        outputs = [o.strip() for o in args.accuracy_outputs.split(",") if o.strip()]
    acc = accuracy_for(scene, outputs=outputs, tol=args.accuracy_tol)
    if acc is None:
        return scene, None, None
    if args.method not in (None, "gen-alpha"):
        raise ValueError(f"fidelity selection chooses a generalized-alpha step; --method {args.method} "
                         f"needs --no-fidelity")
    report = select(scene, acc, t_end=t_end, out_dt=dt, step=args.step)
    path = report.write_json(out / "fidelity.json")
    print(report.text())
    print(f"fidelity report -> {path}")
    res = report.chosen_result
    if res is not None and abs(res.time[-1] - t_end) > 1e-9:
        res = None
    return configure(scene, report.chosen.config), report.chosen.config.step, res


def _add_simulate(sub):
    p = sub.add_parser("simulate", help="simulate a scene file and write results.csv and results.png")
    p.add_argument("scene", help="scene TOML file")
    p.add_argument("--t-end", type=float, default=None, help="end time [s] (default: scene t_end)")
    p.add_argument("--dt", type=float, default=None, help="output interval [s] (default: scene output_step)")
    p.add_argument("--step", type=float, default=None, help="solver step [s] (default: scene solver.step)")
    p.add_argument("--method", choices=("gen-alpha", "radau", "dop853"), default=None)
    p.add_argument("--out", default="results", help="output directory (default: results/)")
    p.add_argument("--accuracy-outputs", default=None, metavar="NAMES",
                   help="fidelity selection: comma-separated outputs (overrides [accuracy].outputs)")
    p.add_argument("--accuracy-tol", type=float, default=None, metavar="TOL",
                   help="fidelity selection: tolerance, m or rad for positions/angles, fraction of the peak "
                        "otherwise (overrides [accuracy].tol; docs/fidelity.md)")
    p.add_argument("--no-fidelity", action="store_true",
                   help="ignore [accuracy] and run the scene as written")
    _add_set(p)
    p.add_argument("--output-dt", type=float, default=None, help="output interval of results.csv [s] (thins "
                                                                  "the --dt samples)")
    p.add_argument("--parquet", action="store_true", help="also write results.parquet")
    p.set_defaults(func=cmd_simulate)


def _lazy(sub, name, module, func, help_, configure):
    p = sub.add_parser(name, help=help_)
    configure(p)

    def run(args):
        import importlib
        mod = importlib.import_module(f"reeve_fmu.{module}")
        return getattr(mod, func)(args)
    p.set_defaults(func=run)


def _add_set(p):
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scene key (rope.EA=90e6, bodies.car.mass=1200, drive.v_max=1.0), a drive "
                        "parameter (torque.max=1500, control.Kp=900, sis.enabled=1) or the load (load=800); "
                        "repeatable (docs/studies.md)")


def _cfg_demo(p):
    p.add_argument("--scene", default=None, help="elevator scene (default: scenes/elevator_2to1.toml)")
    p.add_argument("--load", type=float, default=None, help="payload in the car [kg] (default: rated load)")
    p.add_argument("--landings", default=None, metavar="X1,X2,...",
                   help="car positions [m] visited in order (default: lowest, highest, lowest landing)")
    p.add_argument("--dwell", type=float, default=None, help="rest between moves [s] (default 3)")
    _add_set(p)
    p.add_argument("--levelling", choices=("both", "encoder"), default="both",
                   help="both (default): also run the trip with the shaft information system and compare "
                        "the stopping errors; encoder: motor encoder only")
    p.add_argument("--out", default="results", help="output directory (default: results/)")
    p.add_argument("--step", type=float, default=1e-3, help="communication step [s]")
    p.add_argument("--output-dt", type=float, default=None, help="output interval of results.csv [s] "
                                                                  "(default: every step)")
    p.add_argument("--parquet", action="store_true", help="also write results.parquet")
    p.add_argument("--rebuild", action="store_true", help="rebuild the FMUs even if up to date")
    p.add_argument("--no-progress", action="store_true")


def _cfg_sweep(p):
    p.add_argument("study", help="study TOML file (docs/studies.md)")
    p.add_argument("--out", default="results/sweep", help="output directory (default: results/sweep/)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="address of an existing Dask scheduler (default: a local cluster)")
    p.add_argument("--workers", type=int, default=None, help="local cluster size (default: every core)")
    p.add_argument("--no-progress", action="store_true")


def _cfg_build(p):
    p.add_argument("--scene", default=None, help="plant scene (default: scenes/elevator_2to1.toml); a crane scene "
                   "(a body on a revolute joint and a hoist drive) builds a crane plant FMU and CraneDrive.fmu")
    p.add_argument("--name", default=None, help="plant FMU model name (default: ReevingPlant for the reference "
                   "scene scenes/elevator_2to1.toml as it is, CranePlant for scenes/slewing_crane.toml as it is, "
                   "Plant_<scene name> for any other scene or --set)")
    p.add_argument("--dest", default=None, help="output directory (default: fmus/, with --fmi 3 fmus/fmi3/)")
    p.add_argument("--fmi", type=int, choices=(2, 3), default=2, help="FMI version of the co-simulation FMUs "
                   "(default 2; 3: FMI 3.0, docs/fmu-hosts.md)")
    p.add_argument("--standalone", action="store_true", help="FMUs that carry their Python runtime (libpython, "
                   "stdlib, numpy, numba): a native host runs them on a machine without Python (docs/fmu-hosts.md)")
    _add_set(p)


def _cfg_bench(p):
    p.add_argument("--quick", action="store_true", help="the short suite (<= 3 min)")
    p.add_argument("--out", default="bench", help="output directory")


def _cfg_crane(p):
    p.add_argument("scene", help="crane scene TOML (e.g. scenes/crane_8fall.toml)")
    p.add_argument("--out", default="results/crane", help="output directory")
    p.add_argument("--heights", type=int, default=None, help="number of hoist heights (default: scene)")
    _add_set(p)


def _cfg_hil(p):
    p.add_argument("--bus", choices=("virtual", "udp_multicast"), default="virtual")
    p.add_argument("--multicast", choices=("host", "route", "lan"), default="host",
                   help="udp_multicast: host (default: the sockets keep the frames on this host; nothing on the "
                        "host is changed), route (also route the bench's group /32 to lo while it runs: root, "
                        "said on the console, undone at exit), lan (TTL 1 on the default interface: a controller "
                        "on another host)")
    p.add_argument("--controller", choices=("builtin", "external"), default="builtin")
    p.add_argument("--realtime", action="store_true", help="pace SYNC to the wall clock")
    p.add_argument("--inject", action="append", default=[], metavar="FAULT",
                   help="loss=P | delay=MS | controller-dies-at=T (repeatable)")
    p.add_argument("--out", default="results/hil", help="output directory")
    p.add_argument("--t-end", type=float, default=None, help="stop after T seconds of trip")
    _add_set(p)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="reeve-fmu", description=__doc__.splitlines()[0],
                                 epilog="--debug (anywhere): print the traceback of a failure. Exit codes: 0 done, "
                                        "1 internal error, 2 bad input, 3 run stopped by an event.")
    sub = ap.add_subparsers(dest="command", required=True)
    _add_simulate(sub)
    _lazy(sub, "demo", "demo", "cli_demo", "build the FMUs if needed and co-simulate the 2:1 elevator trip", _cfg_demo)
    _lazy(sub, "build", "demo", "cli_build", "build the plant and electric-drive FMUs into fmus/", _cfg_build)
    _lazy(sub, "sweep", "studies.sweep", "cli_sweep", "parameter/load-case sweep of elevator trips on Dask",
          _cfg_sweep)
    _lazy(sub, "bench", "studies.bench", "cli_bench", "speed-against-error benchmark", _cfg_bench)
    _lazy(sub, "crane", "studies.crane", "cli_crane", "hoist sweep of a crane (statics of the dynamic model): hook-block rotation", _cfg_crane)
    _lazy(sub, "hil", "hil.cli", "cli_hil", "motor controller in the loop over CAN (CiA 402)", _cfg_hil)
    argv = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in argv or os.environ.get("REEVE_FMU_DEBUG", "") not in ("", "0")
    argv = [a for a in argv if a != "--debug"]
    args = ap.parse_args(argv)
    return run_command(args, debug)


EXIT_INTERNAL, EXIT_BAD_INPUT, EXIT_EVENT = 1, 2, 3   # documented in README.md, "Exit codes"


def _cosim_stopped(exc) -> bool:
    """A co-simulation that ended at a failed step after writing its results (demo)."""
    from .fmu.master import CosimError
    return isinstance(exc, CosimError) and exc.time is not None


def run_command(args, debug: bool = False) -> int:
    """Run a subcommand: every failure becomes one line on stderr and an exit code (README "Exit
    codes"); --debug (or REEVE_FMU_DEBUG=1) adds the traceback."""
    from .core.scene import SceneError
    from .core.solver import SolverError
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print(f"reeve-fmu {args.command}: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # noqa: BLE001 - the one place that turns exceptions into exit codes
        if debug:
            import traceback
            traceback.print_exc()
        text = str(exc).strip() or type(exc).__name__
        if isinstance(exc, SolverError) and exc.time is not None or _cosim_stopped(exc):
            rc, what = EXIT_EVENT, f"run stopped by an event: {text}"
        elif isinstance(exc, (SceneError, SolverError, ValueError, OSError)) and not _numpy_internal(exc):
            rc, what = EXIT_BAD_INPUT, f"error: {text}"
        else:
            rc = EXIT_INTERNAL
            where = _where(exc)
            what = (f"internal error: {type(exc).__name__}: {text.splitlines()[0]}{where}. The scene may be "
                    f"physically wrong in a way no check catches (see docs/hard-cases.md, \"Physically "
                    f"wrong input\")" + ("" if debug else "; run again with --debug for the traceback"))
        print(f"reeve-fmu {args.command}: {what}", file=sys.stderr)
        return rc


def _numpy_internal(exc) -> bool:
    """numpy's LinAlgError is a ValueError but says nothing about the input."""
    return type(exc).__name__ == "LinAlgError"


def _where(exc) -> str:
    """' (in module.function)' of the innermost frame of the package that raised."""
    import traceback
    frames = [f for f in traceback.extract_tb(exc.__traceback__) if "reeve_fmu" in f.filename]
    if not frames:
        return ""
    f = frames[-1]
    return f" (in {Path(f.filename).stem}.{f.name})"


if __name__ == "__main__":
    sys.exit(main())
