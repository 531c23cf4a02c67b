"""Property-based bad-scene tests (docs/hard-cases.md, "Bad scene files"): delete, retype or negate any key of the shipped
scenes. Every mutation must either still build or fail with a SceneError that names the file and the
mutated key - never an unhandled exception from inside the code."""
import copy

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from reeve_fmu.core.model import build_model
from reeve_fmu.core.scene import SceneError, parse_scene
from reeve_fmu.core.solver import SolverError, Simulator
from tests.support import ROOT
from tests.support.checks import check

SCENES = sorted(p for p in (ROOT / "scenes").rglob("*.toml") if "crane" not in p.name)


def leaves(node, path=()):
    """Every (path, value) of a TOML document, tables and arrays included."""
    out = []
    if isinstance(node, dict):
        for k, v in node.items():
            out.append((path + (k,), v))
            out.extend(leaves(v, path + (k,)))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            if isinstance(v, (dict, list)):
                out.append((path + (i,), v))
                out.extend(leaves(v, path + (i,)))
    return out


def key_text(path):
    """How SceneError spells a key path: bodies[0].mass, ropes[0].route[1].anchor, scene.model."""
    s = ""
    for p in path:
        s += f"[{p}]" if isinstance(p, int) else (f".{p}" if s else p)
    return s


def mutate(doc, path, how):
    doc = copy.deepcopy(doc)
    parent = doc
    for p in path[:-1]:
        parent = parent[p]
    k = path[-1]
    if how == "delete":
        if isinstance(parent, list):
            parent.pop(k)
        else:
            del parent[k]
    elif how == "retype":
        v = parent[k]
        parent[k] = "x" if not isinstance(v, str) else 3.5
    elif how == "negate":
        v = parent[k]
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            parent[k] = [] if not isinstance(v, list) else {"bad": 1}
        else:
            parent[k] = -v if v != 0 else -1.0
    return doc


DOCS = {p.name: tomllib.loads(p.read_text(encoding="utf-8")) for p in SCENES}
PATHS = {name: leaves(doc) for name, doc in DOCS.items()}


@settings(max_examples=250, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow])
@given(scene=st.sampled_from(sorted(DOCS)), data=st.data(),
       how=st.sampled_from(["delete", "retype", "negate"]))
def test_mutated_scene_builds_or_names_the_key(scene, data, how):
    path, _ = data.draw(st.sampled_from(PATHS[scene]))
    doc = mutate(DOCS[scene], path, how)
    try:
        sc = parse_scene(doc, scene)
        build_model(sc)
    except SceneError as exc:
        check_message(str(exc), scene, path, doc)


def all_key_paths(doc):
    return {key_text(p) for p, _ in leaves(doc)}


def check_message(msg, scene, path, doc):
    """The error starts with the file, and its [key path] is the mutated key, one of its parents, or
    another key of the document that the mutation made inconsistent (e.g. deleting a sheave's kind
    makes the drive.sheave reference an idler)."""
    assert msg.startswith(f"{scene}: "), msg
    assert "[" in msg and "]" in msg, msg
    named = msg.split("[", 1)[1].split("] ", 1)[0]
    parents = [key_text(path[:i]) for i in range(len(path), 0, -1)]
    assert (named in parents or named in all_key_paths(doc) or named in all_key_paths(DOCS[scene])
            or any(named.startswith(p) for p in parents if p)), msg


def test_every_single_key_mutation_is_handled():
    """Deterministic sweep over every key of every shipped scene x {delete, retype, negate}."""
    counts = {"built": 0, "error": 0}
    for name, paths in PATHS.items():
        for path, _ in paths:
            for how in ("delete", "retype", "negate"):
                doc = mutate(DOCS[name], path, how)
                try:
                    build_model(parse_scene(doc, name))
                    counts["built"] += 1
                except SceneError as exc:
                    check_message(str(exc), name, path, doc)
                    counts["error"] += 1
    assert counts["error"] > 1000 and counts["built"] > 0


# bound of max |acceleration| (m/s^2) at the start of each shipped scene (the run records the residual
# and fails a bound more than 10x above it, tests/support/checks.py). The statics is solved with the
# bilateral law, which the (default) tension-only law is exactly on a taut rope.
STATICS_RESIDUAL = {
    "buffer_impact.toml": 4e-8,
    "elevator_1to1_highrise.toml": 1.5e-8,
    "elevator_2to1.toml": 3e-7,
    "emergency_stop.toml": 1e-4,              # 64 elements per span
    "hanging_rope.toml": 4e-12,
    "slack_hard_stop.toml": 2.4e-7,
    "traction_en81.toml": 1.2e-11,
    "vanishing_span.toml": 3e-7,
}


@pytest.mark.parametrize("path", SCENES, ids=lambda p: p.name)
def test_shipped_scenes_solve_statics(path):
    """Unmutated scenes: the initial statics converges to an equilibrium: the bodies and free material
    coordinates start at rest with (near) zero acceleration, each scene within its bound in
    STATICS_RESIDUAL (a new scene needs one there, within 10x of its residual)."""
    from reeve_fmu.core.scene import load_scene
    assert path.name in STATICS_RESIDUAL, f"{path.name}: add a bound of its statics residual to STATICS_RESIDUAL"
    sc = load_scene(path)
    m = build_model(sc)
    st = Simulator(m).initial_state()
    eq = list(m.statics_equations)
    assert np.all(st.v == 0.0)
    check("max |acceleration| at the start [m/s^2]", st.qdd[eq], STATICS_RESIDUAL[path.name])
