"""Command line: reeve-fmu simulate | demo | build | bench | crane | hil.

Front ends import the layers below them; each subcommand's implementation lives in its own module and
is imported only when used, so `reeve-fmu simulate` does not load fmpy or python-can.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

PACKAGE_DIR = Path(__file__).resolve().parent


from .core.scene import default_scene  # noqa: E402,F401  (re-exported)


def cmd_simulate(args) -> int:
    from .core.model import build_model
    from .core.results import plot_overview, write_csv
    from .core.scene import load_scene
    from .core.solver import Simulator

    scene = load_scene(args.scene)
    t_end = args.t_end if args.t_end is not None else scene.t_end
    dt = args.dt if args.dt is not None else scene.output_step
    out = Path(args.out)
    scene, chosen_step, res = _fidelity(args, scene, t_end, dt, out)
    reused = res is not None
    t0 = time.perf_counter()
    if res is None:    # (the fidelity selection's full-run check already ran the chosen configuration)
        step = chosen_step if chosen_step is not None else args.step
        res = Simulator(build_model(scene), method=args.method, step=step).run(t_end, dt)
    wall = time.perf_counter() - t0
    out.mkdir(parents=True, exist_ok=True)
    cols = res.as_dict()
    time_ = cols.pop("time")
    write_csv(out / "results.csv", time_, cols)
    plot_overview(out / "results.png", time_, cols, title=f"{scene.name} ({scene.model})")
    how = ("(the run of the fidelity full-run check)" if reused else
           f"in {wall:.2f} s (incl. statics and JIT load; {t_end / wall:.0f}x real time)")
    print(f"{scene.name}: {len(time_)} samples to t = {time_[-1]:.3f} s {how} -> {out}/results.csv, results.png")
    return 0


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
    p.set_defaults(func=cmd_simulate)


def _lazy(sub, name, module, func, help_, configure):
    p = sub.add_parser(name, help=help_)
    configure(p)

    def run(args):
        import importlib
        mod = importlib.import_module(f"reeve_fmu.{module}")
        return getattr(mod, func)(args)
    p.set_defaults(func=run)


def _cfg_demo(p):
    p.add_argument("--out", default="results", help="output directory (default: results/)")
    p.add_argument("--step", type=float, default=1e-3, help="communication step [s]")
    p.add_argument("--rebuild", action="store_true", help="rebuild the FMUs even if up to date")
    p.add_argument("--no-progress", action="store_true")


def _cfg_build(p):
    p.add_argument("--scene", default=None, help="plant scene (default: scenes/elevator_2to1.toml)")
    p.add_argument("--name", default=None, help="plant FMU model name (default: ReevingPlant)")
    p.add_argument("--dest", default="fmus", help="output directory (default: fmus/)")


def _cfg_bench(p):
    p.add_argument("--quick", action="store_true", help="the short suite (<= 3 min)")
    p.add_argument("--out", default="bench", help="output directory")


def _cfg_crane(p):
    p.add_argument("scene", help="crane scene TOML (e.g. scenes/crane_8fall.toml)")
    p.add_argument("--out", default="results/crane", help="output directory")
    p.add_argument("--heights", type=int, default=None, help="number of hoist heights (default: scene)")


def _cfg_hil(p):
    p.add_argument("--bus", choices=("virtual", "udp_multicast"), default="virtual")
    p.add_argument("--controller", choices=("builtin", "external"), default="builtin")
    p.add_argument("--realtime", action="store_true", help="pace SYNC to the wall clock")
    p.add_argument("--inject", action="append", default=[], metavar="FAULT",
                   help="loss=P | delay=MS | controller-dies-at=T (repeatable)")
    p.add_argument("--out", default="results/hil", help="output directory")
    p.add_argument("--t-end", type=float, default=None, help="stop after T seconds of trip")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="reeve-fmu", description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="command", required=True)
    _add_simulate(sub)
    _lazy(sub, "demo", "demo", "cli_demo", "build the FMUs if needed and co-simulate the 2:1 elevator trip", _cfg_demo)
    _lazy(sub, "build", "demo", "cli_build", "build the plant and electric-drive FMUs into fmus/", _cfg_build)
    _lazy(sub, "bench", "studies.bench", "cli_bench", "speed-against-error benchmark", _cfg_bench)
    _lazy(sub, "crane", "studies.crane", "cli_crane", "quasi-static hoist sweep of a crane: hook-block rotation", _cfg_crane)
    _lazy(sub, "hil", "hil.run", "cli_hil", "motor controller in the loop over CAN (CiA 402)", _cfg_hil)
    args = ap.parse_args(argv)
    from .core.scene import SceneError
    from .core.solver import SolverError
    try:
        rc = int(args.func(args) or 0)
    except (SceneError, SolverError, ValueError, FileNotFoundError) as exc:
        print(f"reeve-fmu {args.command}: error: {exc}", file=sys.stderr)
        rc = 2
    return rc


if __name__ == "__main__":
    sys.exit(main())
