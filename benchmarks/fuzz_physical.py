"""Fuzz the shipped scenes with physically wrong but well-formed values.

For every scene under scenes/ (hard cases included): every numeric key (a vector or table as a
whole) scaled by 1e-6, 1e-3, 1e3, 1e6 and sign-flipped, every wrap sense flipped, every body moved
+-1 m along x, y and z. Each case is parsed, checked (core/plausibility.py), built, brought to its
initial statics and stepped a few solver steps (crane scenes: the quasi-static sweep at 3 heights).
A case passes when it runs, or stops with a clear error (SceneError / SolverError / CraneError / a
ValueError naming a key); it fails on any other exception (a traceback), a non-finite output or a
case that runs out of time.

    python benchmarks/fuzz_physical.py [--jobs 2] [--timeout 120] [--json docs/img/fuzz_physical.json]

prints the counts (cases, errors, warnings, runs, failures) that docs/hard-cases.md quotes.
tests/test_physical_fuzz.py runs a deterministic sample of the same cases.
"""
from __future__ import annotations

import argparse
import copy
import json
import math
import os
from pathlib import Path
import signal
import sys
import time
import traceback

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[1]
FACTORS = (1e-6, 1e-3, 1e3, 1e6, -1.0)
STEPS = 5                # solver steps after the statics
CRANE_HEIGHTS = 3


def scenes():
    return sorted(p for p in (ROOT / "scenes").rglob("*.toml"))


def _numeric_leaves(node, path=()):
    """(path, value) of every number, numeric vector and [t, v] table of a TOML document."""
    out = []
    if isinstance(node, dict):
        for k, v in node.items():
            if k == "route" and isinstance(v, list):
                for i, stop in enumerate(v):
                    out.extend(_numeric_leaves(stop, path + (k, i)))
            elif isinstance(v, (dict, list)) and not _is_numeric(v):
                out.extend(_numeric_leaves(v, path + (k,)))
            elif _is_numeric(v):
                out.append((path + (k,), v))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            out.extend(_numeric_leaves(v, path + (i,)))
    return out


def _is_numeric(v):
    if isinstance(v, bool):
        return False
    if isinstance(v, (int, float)):
        return True
    return isinstance(v, list) and len(v) > 0 and all(_is_numeric(x) for x in v)


def key_text(path):
    """The key path as the scene errors spell it: bodies[0].mass, ropes[0].route[1].wrap."""
    s = ""
    for p in path:
        s += f"[{p}]" if isinstance(p, int) else (f".{p}" if s else p)
    return s


def _scale(v, f):
    if isinstance(v, list):
        return [_scale(x, f) for x in v]
    if isinstance(v, int):
        return int(round(v * f)) if abs(v * f) < 2 ** 62 else v
    return v * f


def cases():
    """Every case, in a fixed order: dicts (scene, label, kind, path, arg)."""
    out = []
    for p in scenes():
        rel = str(p.relative_to(ROOT))
        doc = tomllib.loads(p.read_text(encoding="utf-8"))
        for path, _ in _numeric_leaves(doc):
            for f in FACTORS:
                out.append(dict(scene=rel, kind="scale", path=list(path), arg=f,
                                label=f"{key_text(path)} x {f:g}"))
        for i, rope in enumerate(doc.get("ropes", [])):
            for k, stop in enumerate(rope.get("route", [])):
                if "sheave" in stop:
                    out.append(dict(scene=rel, kind="wrap", path=["ropes", i, "route", k], arg=None,
                                    label=f"ropes[{i}].route[{k}].wrap flipped"))
        for i, body in enumerate(doc.get("bodies", [])):
            for ax in range(3):
                for d in (-1.0, 1.0):
                    out.append(dict(scene=rel, kind="move", path=["bodies", i], arg=[ax, d],
                                    label=f"bodies[{i}].position {'xyz'[ax]} {d:+g} m"))
    return out


def mutated(case):
    doc = tomllib.loads((ROOT / case["scene"]).read_text(encoding="utf-8"))
    node = doc
    path = case["path"]
    for p in path[:-1]:
        node = node[p]
    k = path[-1]
    if case["kind"] == "scale":
        node[k] = _scale(node[k], case["arg"])
    elif case["kind"] == "wrap":
        stop = node[k]
        stop["wrap"] = "ccw" if stop.get("wrap", "ccw") == "cw" else "cw"
    else:
        body = node[k]
        pos = list(body.get("position", [0.0, 0.0, 0.0]))
        ax, d = case["arg"]
        pos[ax] = pos[ax] + d
        body["position"] = pos
    return doc


class _Timeout(Exception):
    pass


def _alarm(signum, frame):
    raise _Timeout()


def run_case(case, timeout: float = 120.0) -> dict:
    """Outcome of one case: run | error | fail-traceback | fail-nan | fail-timeout, with the message
    and the plausibility warnings."""
    t0 = time.perf_counter()
    res = dict(case=case["label"], scene=case["scene"], warnings=[], message="")
    old = signal.signal(signal.SIGALRM, _alarm) if timeout else None
    if timeout:
        signal.setitimer(signal.ITIMER_REAL, timeout)
    try:
        res.update(_run(case))
    except _Timeout:
        res.update(outcome="fail-timeout", message=f"no answer within {timeout:g} s")
    except Exception as exc:  # noqa: BLE001 - classified here
        res.update(_classify(exc))
    finally:
        if timeout:
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, old)
    res["seconds"] = time.perf_counter() - t0
    return res


def _classify(exc):
    from reeve_fmu.core.scene import SceneError
    from reeve_fmu.core.solver import SolverError
    from reeve_fmu.studies.crane import CraneError
    text = str(exc).strip()
    clear = isinstance(exc, (SceneError, SolverError, CraneError)) or (
        type(exc) is ValueError and "[" in text)
    if clear and text:
        return dict(outcome="error", message=text.splitlines()[0], error=type(exc).__name__)
    return dict(outcome="fail-traceback", message=f"{type(exc).__name__}: {text}",
                traceback=traceback.format_exc())


def _run(case):
    import numpy as np
    from reeve_fmu.core.plausibility import check_or_raise
    from reeve_fmu.core.scene import parse_scene
    doc = mutated(case)
    scene = parse_scene(doc, f"{case['scene']} ({case['label']})")
    warnings = check_or_raise(scene)
    if "crane" in scene.extra:
        from reeve_fmu.studies.crane import build_crane, sweep
        crane = build_crane(scene)
        r = sweep(crane, np.linspace(crane.spec.height_min, crane.spec.height_max, CRANE_HEIGHTS))
        yaw = r.columns["block.yaw"]
        # NaN marks heights with no equilibrium (docs/crane.md); at the first height only a
        # plausibility warning may explain it
        if not np.isfinite(yaw[0]) and not warnings:
            return dict(outcome="fail-nan", message="no equilibrium at the first height and no warning",
                        warnings=warnings)
        return dict(outcome="run", warnings=warnings)
    from reeve_fmu.core.model import build_model
    from reeve_fmu.core.solver import Simulator, SolverError
    sim = Simulator(build_model(scene))
    st = sim.initial_state()
    y = sim.outputs(st)
    if np.any(np.isnan(y)):     # (+inf is a documented value: traction_ratio of a slack span)
        bad = [n for n, v in zip(sim.model.output_names, y) if math.isnan(v)]
        return dict(outcome="fail-nan", message=f"NaN outputs after the statics: {bad}", warnings=warnings)
    try:
        sim.advance(st, st.t + STEPS * sim.h)
    except SolverError as exc:
        warnings = warnings + [f"event: {exc}"]
    y = sim.outputs(st)
    if np.any(np.isnan(y)) or np.any(np.isnan(st.q)):
        bad = [n for n, v in zip(sim.model.output_names, y) if math.isnan(v)]
        return dict(outcome="fail-nan", message=f"NaN outputs after {STEPS} steps: {bad}", warnings=warnings)
    return dict(outcome="run", warnings=warnings + sim.warnings)


def warm_up():
    """Load (or compile) the numba kernels outside any case's time limit: one unchanged run of every
    scene the cases use (dense and banded Newton paths, cranes). A timeout inside a compile leaves
    numba's library half-built for the rest of the process, and a cold compile of a path no warm-up
    run took (e.g. the banded one of a 64-element scene) takes minutes on a loaded machine."""
    first = {}
    for c in cases():
        if c["kind"] == "scale":
            first.setdefault(c["scene"], dict(c, arg=1.0, label="warm-up"))   # a key of it x 1: unchanged
    for case in first.values():
        run_case(case, timeout=0)


def _worker(args):
    case, timeout = args
    return run_case(case, timeout)


def summarize(results) -> dict:
    out = {"cases": len(results)}
    for key in ("run", "error", "fail-traceback", "fail-nan", "fail-timeout"):
        out[key] = sum(r["outcome"] == key for r in results)
    errors = [r for r in results if r["outcome"] == "error"]
    out["errors_by_kind"] = {
        "scene syntax and ranges (parser)": sum(r["error"] == "SceneError" and "initial.statics" not in r["message"]
                                                for r in errors),
        "plausibility": sum(r["error"] == "PlausibilityError" for r in errors),
        "no static equilibrium / statics mode": sum(r["error"] == "SolverError" or "initial.statics" in r["message"]
                                                    for r in errors),
        "crane": sum(r["error"] == "CraneError" for r in errors),
        "other (ValueError naming a key)": sum(r["error"] == "ValueError" for r in errors)}
    out["runs_stopped_by_an_event_in_the_steps"] = sum(
        r["outcome"] == "run" and any(w.startswith("event:") for w in r["warnings"]) for r in results)
    out["runs_with_warnings"] = sum(r["outcome"] == "run" and bool(r["warnings"]) for r in results)
    out["runs_without_warnings"] = out["run"] - out["runs_with_warnings"]
    out["failures"] = out["fail-traceback"] + out["fail-nan"] + out["fail-timeout"]
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=2, help="parallel processes (default 2)")
    ap.add_argument("--timeout", type=float, default=120.0, help="seconds per case (default 120)")
    ap.add_argument("--json", default=None, help="write the counts and every failure here")
    ap.add_argument("--every", type=int, default=1, help="only every N-th case (a quick look)")
    args = ap.parse_args(argv)
    todo = cases()[::args.every]
    t0 = time.perf_counter()
    if args.jobs > 1:
        import multiprocessing as mp
        with mp.get_context("fork").Pool(args.jobs, initializer=warm_up) as pool:
            results = []
            for k, r in enumerate(pool.imap(_worker, [(c, args.timeout) for c in todo], chunksize=4)):
                results.append(r)
                if r["outcome"].startswith("fail"):
                    print(f"FAIL {r['scene']}: {r['case']}: {r['message']}", flush=True)
                if (k + 1) % 200 == 0:
                    print(f"... {k + 1}/{len(todo)} cases, {time.perf_counter() - t0:.0f} s", flush=True)
    else:
        warm_up()
        results = [run_case(c, args.timeout) for c in todo]
    wall = time.perf_counter() - t0
    summ = summarize(results)
    summ.update(wall_seconds=round(wall, 1), jobs=args.jobs, load_average=os.getloadavg()[0],
                slowest_case_seconds=round(max(r["seconds"] for r in results), 2))
    print(json.dumps(summ, indent=2))
    if args.json:
        fails = [r for r in results if r["outcome"].startswith("fail")]
        Path(args.json).write_text(json.dumps({"summary": summ, "failures": fails}, indent=2) + "\n", encoding="utf-8")
    return 1 if summ["failures"] else 0


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    sys.exit(main())
