"""Fuzz the shipped scenes with physically wrong but well-formed values.

For every scene under scenes/ (hard cases included): every numeric key (a vector or table as a
whole) scaled by 1e-6, 1e-3, 1e3, 1e6 and sign-flipped, every wrap sense flipped, every body moved
+-1 m along x, y and z. Each case is parsed, checked (core/plausibility.py), built, brought to its
initial statics and stepped a few solver steps (crane scenes: the quasi-static sweep at 3 heights).
A case passes when it runs, or stops with a clear error (SceneError / SolverError / CraneError / a
ValueError) that names a key of the scene or one of its bodies, sheaves or ropes; it fails on any
other exception (a traceback), an error that names nothing, a non-finite output or a case that runs
out of time.

Every elevator scene also gets geometry and capacity mutations that no real elevator has (a
counterweight or car above the sheaves that carry it, a sheave radius in mm, ropes too short for
their route, a brake or drive that cannot hold the car, counterweight and rated load far off balance,
a load above max_load). Each is taken through the study path — plausibility, the initial statics,
the trip case (holding torques, drive sizing) and the static EN 81-20/-50 verdicts — and passes only
when it stops with an error naming one of the case's keys, or (where the case allows it) ends in a
FAIL verdict: never a PASS, never a traceback.

    python benchmarks/fuzz_physical.py [--jobs 2] [--timeout 120] [--json docs/img/fuzz_physical.json]

prints the counts (cases, errors, warnings, runs, failures) that docs/hard-cases.md quotes.
tests/studies/test_physical_fuzz.py runs a deterministic sample of the same cases.
"""
from __future__ import annotations

import argparse
import copy
import json
import math
import os
from pathlib import Path
import re
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
        if "elevator" in doc:
            out.extend(study_cases(rel, doc))
    return out


# study mutations: (name, keys an error may name, whether a FAIL verdict is an acceptable end)
STUDY_MUTATIONS = (
    ("counterweight above its top sheave", ("bodies[{cw}].position",), False),
    ("car above its top sheave", ("bodies[{car}].position",), False),
    ("traction sheave radius in mm", ("sheaves[{traction}].radius",), False),
    ("ropes 5 m long for rope-length statics", ("ropes[0].length",), False),
    ("brake.torque x 0.1", ("brake.torque",), False),
    ("brake.torque between the rated-load and 125 % holding torques", (), True),
    ("drive torque.max x 0.3", ("torque.max",), False),
    ("counterweight mass x 0.1", ("brake.torque",), True),
    ("counterweight mass x 10", ("brake.torque",), True),
    ("rated_load x 3", ("brake.torque",), True),
    ("load above max_load", ("elevator.max_load",), False),
)


def study_cases(rel, doc):
    el = doc["elevator"]
    names = [b["name"] for b in doc["bodies"]]
    sheaves = [s["name"] for s in doc.get("sheaves", [])]
    idx = {"cw": names.index(el.get("counterweight", "counterweight")), "car": names.index(el.get("car", "car")),
           "traction": sheaves.index(doc["drive"]["sheave"])}
    return [dict(scene=rel, kind="study", path=[], arg=name, label=f"study: {name}",
                 keys=[k.format(**idx) for k in keys], fail_ok=fail_ok, index=idx)
            for name, keys, fail_ok in STUDY_MUTATIONS]


def _top(doc):
    """Height of the highest fixed stop (ground sheaves and anchors) of the scene."""
    zs = [s["center"][2] for s in doc.get("sheaves", []) if not s.get("body")]
    zs += [st["at"][2] for r in doc["ropes"] for st in r["route"] if st.get("anchor") == "ground"]
    return max(zs)


def _study_mutated(case):
    """(scene document, load kg or None, drive --set values) of a study mutation."""
    doc = tomllib.loads((ROOT / case["scene"]).read_text(encoding="utf-8"))
    name, i = case["arg"], case["index"]
    load, sets = None, {}
    if name.endswith("above its top sheave"):
        body = doc["bodies"][i["cw" if name.startswith("counterweight") else "car"]]
        body["position"] = [body["position"][0], body["position"][1], _top(doc) + 3.0]
    elif name == "traction sheave radius in mm":
        doc["sheaves"][i["traction"]]["radius"] *= 1e3
    elif name.startswith("ropes 5 m"):
        doc.setdefault("initial", {})["statics"] = "rope-length"
        for r in doc["ropes"]:
            r["length"] = 5.0
    elif name == "brake.torque x 0.1":
        doc["brake"]["torque"] *= 0.1
    elif name.startswith("brake.torque between"):
        from reeve_fmu.core.scene import parse_scene
        from reeve_fmu.studies.verdicts import brake_cases
        bc = brake_cases(parse_scene(copy.deepcopy(doc), case["scene"]))
        rated, full = (max(abs(t) for t in bc["hold"][m]) for m in sorted(bc["hold"])[1:])
        doc["brake"]["torque"] = 0.5 * (rated + full)
    elif name == "drive torque.max x 0.3":
        from reeve_fmu.core.scene import parse_scene
        from reeve_fmu.studies.trip import sized_drive
        sets = {"torque.max": 0.3 * sized_drive(parse_scene(copy.deepcopy(doc), case["scene"]))["torque.max"]}
    elif name.startswith("counterweight mass"):
        doc["bodies"][i["cw"]]["mass"] *= 0.1 if name.endswith("0.1") else 10.0
    elif name == "rated_load x 3":
        doc["elevator"]["rated_load"] *= 3.0
        doc["elevator"].pop("max_load", None)
    elif name == "load above max_load":
        el = doc["elevator"]
        load = 1.01 * el.get("max_load", 1.25 * el["rated_load"])
    return doc, load, sets


def _run_study(case):
    """The study path of a mutation: plausibility, initial statics, trip case, static verdicts."""
    from reeve_fmu.core.model import build_model
    from reeve_fmu.core.plausibility import check_or_raise, initial_statics
    from reeve_fmu.core.scene import parse_scene
    from reeve_fmu.core.solver import Simulator
    from reeve_fmu.studies.analysis import traction_limits
    from reeve_fmu.studies.trip import trip_case
    from reeve_fmu.studies.verdicts import brake_verdicts, en81_verdicts, worst
    doc, load, sets = _study_mutated(case)
    scene = parse_scene(doc, source(case))
    warnings = check_or_raise(scene)
    initial_statics(Simulator(build_model(scene)))
    tc = trip_case(scene, load=load, sets=sets)
    vs = en81_verdicts(tc.scene, traction_limits(tc.scene)) + brake_verdicts(tc.scene)
    return dict(outcome="run", verdict=worst(vs), warnings=warnings,
                message="; ".join(v.line() for v in vs if v.status != "PASS"))


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
        if res["outcome"] == "error" and not names_a_key(res["full_message"], case) \
                and not (isinstance(getattr(exc, "time", None), float)):     # (a run-time event names its time)
            res.update(outcome="fail-nokey")
    finally:
        if timeout:
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, old)
    res["seconds"] = time.perf_counter() - t0
    if case["kind"] == "study":
        res["study_failure"] = study_failure(case, res)
    return res


#: a scene key in an error message: bodies[0].mass, ropes[1].route[2], solver.min_span, brake.torque, a
#: drive parameter (torque.max)
KEY_RE = re.compile(r"\b(?:bodies|sheaves|ropes|buffers)\[\d+\]|\b(?:scene|solver|drive|brake|initial|elevator|"
                    r"crane|accuracy|torque|control|trip|sis|car)\.[A-Za-z_]")


def source(case):
    """The scene source a case's scene is parsed under (error messages start with it)."""
    return f"{case['scene']} ({case['label']})"


def names_a_key(text, case):
    """Whether an error message names a scene key, or a body, sheave or rope of the scene by name (the
    case's label, part of the scene source the message starts with, does not count)."""
    text = text.replace(source(case), "")
    if KEY_RE.search(text):
        return True
    doc = tomllib.loads((ROOT / case["scene"]).read_text(encoding="utf-8"))
    names = [x.get("name") for t in ("bodies", "sheaves", "ropes", "buffers") for x in doc.get(t, [])]
    return any(n and f"'{n}'" in text for n in names)


def _classify(exc):
    from reeve_fmu.core.scene import SceneError
    from reeve_fmu.core.solver import SolverError
    from reeve_fmu.studies.crane import CraneError
    text = str(exc).strip()
    # a ValueError of the package (not a subclass such as numpy's LinAlgError) is bad input
    clear = isinstance(exc, (SceneError, SolverError, CraneError)) or type(exc).__name__ in ("ValueError",
                                                                                               "OverrideError")
    if clear and text:
        return dict(outcome="error", message=text.splitlines()[0], full_message=text, error=type(exc).__name__)
    return dict(outcome="fail-traceback", message=f"{type(exc).__name__}: {text}",
                traceback=traceback.format_exc())


def _run(case):
    import numpy as np
    if case["kind"] == "study":
        return _run_study(case)
    from reeve_fmu.core.plausibility import check_or_raise
    from reeve_fmu.core.scene import parse_scene
    doc = mutated(case)
    scene = parse_scene(doc, source(case))
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


def study_failure(case, res):
    """Why a study mutation's outcome is wrong (None when right): a PASS verdict, a FAIL where the case
    must stop with an error, an error that names none of the case's keys, or any failure outcome."""
    if res["outcome"].startswith("fail"):
        return f"{res['outcome']}: {res['message']}"
    if res["outcome"] == "run":
        if res["verdict"] == "PASS":
            return "PASS on an impossible configuration"
        if not case["fail_ok"]:
            return f"{res['verdict']} verdict where an error naming {case['keys']} was expected: {res['message']}"
        return None
    text = res.get("full_message", res["message"]).replace(source(case), "")
    if case["keys"] and not any(k in text for k in case["keys"]):
        return f"the error names none of {case['keys']}: {text}"
    return None


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
    for key in ("run", "error", "fail-traceback", "fail-nokey", "fail-nan", "fail-timeout"):
        out[key] = sum(r["outcome"] == key for r in results)
    errors = [r for r in results if r["outcome"] == "error"]
    out["errors_by_kind"] = {
        "scene syntax and ranges (parser)": sum(r["error"] == "SceneError" and "initial.statics" not in r["message"]
                                                for r in errors),
        "plausibility": sum(r["error"] == "PlausibilityError" for r in errors),
        "no static equilibrium / statics mode": sum(r["error"] == "SolverError" or "initial.statics" in r["message"]
                                                    for r in errors),
        "crane": sum(r["error"] == "CraneError" for r in errors),
        "other (ValueError naming a key)": sum(r["error"] in ("ValueError", "OverrideError") for r in errors)}
    out["runs_stopped_by_an_event_in_the_steps"] = sum(
        r["outcome"] == "run" and any(w.startswith("event:") for w in r["warnings"]) for r in results)
    out["runs_with_warnings"] = sum(r["outcome"] == "run" and bool(r["warnings"]) for r in results)
    out["runs_without_warnings"] = out["run"] - out["runs_with_warnings"]
    out["failures"] = out["fail-traceback"] + out["fail-nokey"] + out["fail-nan"] + out["fail-timeout"]
    study = [r for r in results if r.get("study_failure", "") != ""]
    out["study_mutations"] = len(study)
    out["study_errors_naming_the_key"] = sum(r["outcome"] == "error" and r["study_failure"] is None for r in study)
    out["study_fail_verdicts"] = sum(r["outcome"] == "run" and r["study_failure"] is None for r in study)
    out["study_wrong"] = sum(r["study_failure"] is not None for r in study)
    out["failures"] += out["study_wrong"]
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
                if r["outcome"].startswith("fail") or r.get("study_failure"):
                    print(f"FAIL {r['scene']}: {r['case']}: {r.get('study_failure') or r['message']}", flush=True)
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
        fails = [r for r in results if r["outcome"].startswith("fail") or r.get("study_failure")]
        Path(args.json).write_text(json.dumps({"summary": summ, "failures": fails}, indent=2) + "\n", encoding="utf-8")
    return 1 if summ["failures"] else 0


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    sys.exit(main())
