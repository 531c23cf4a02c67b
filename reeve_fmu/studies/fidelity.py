"""Fidelity selection: model only what a scene needs (docs/fidelity.md).

A scene's `[accuracy]` section (or `reeve-fmu simulate --accuracy-*`) names outputs and a tolerance.
`select` runs a short probe window of the scene with a ladder of candidate configurations (rope model,
elements per span, wrap model, generalized-alpha step), estimates each one's error as the largest
difference from a refined configuration on the common output grid, and picks the cheapest candidate
whose estimate meets the tolerance with a safety margin. Cost is the deterministic proxy
n_dof x n_steps (wall time is measured and reported, never used to decide).

Tolerances: an output whose quantity is a position, an angle or a slip (`car.position`,
`traction.angle`, `car.position.z`) gets an absolute tolerance in its SI unit (m, rad); every other
output (tensions, forces, torques, speeds, accelerations, ratios) a tolerance relative to its peak
|value| in the reference run over the probe window. `tols` overrides per output, also with an explicit
`{ abs = x }` or `{ rel = x }`.

Layering: above scene/model/solver, below cli. Scenes are derived with dataclasses.replace; nothing
here mutates a Scene.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
import itertools
import json
import math
import time

import numpy as np

from ..core.scene import AXES, MODELS, Scene, SceneError, _Reader

DYNAMIC_MODELS = MODELS
MODEL_RANK = {m: i for i, m in enumerate(DYNAMIC_MODELS)}
ABS_QUANTITIES = ("position", "angle", "slip")   # absolute tolerance [m or rad]; everything else relative
# up to 16 elements per span (probe reference at 32): the banded Newton matrix makes those cheap, and
# without the 16 rung nothing passes on the 1:1 high-rise at 1e-4 (docs/fidelity.md)
DEFAULT_ELEMENTS = (1, 2, 4, 8, 16)
DEFAULT_STEP_DIVISORS = (1, 2, 4, 8)             # steps = output interval / divisor
DEFAULT_MARGIN = 0.5                             # a candidate passes if its estimate <= margin * tol
RELIABLE = 0.2                                   # finest candidate vs reference <= RELIABLE * tol
SETTLE = 1.0                                     # s after the acceleration phase in the default probe
OTHER_PROBE = 2.0                                # s, default probe without an S-curve drive
ACCURACY_KEYS = {"outputs", "tol", "tols", "probe", "models", "elements", "wraps", "steps", "margin",
                 "search", "full_check"}


class FidelityError(ValueError):
    """The selection cannot run (e.g. the reference configuration fails)."""


# ---------------------------------------------------------------------------------------- inputs
@dataclass(frozen=True)
class OutputTol:
    name: str
    mode: str        # "abs": |error| <= tol in SI units; "rel": |error| <= tol * peak |reference|
    tol: float


@dataclass(frozen=True)
class Accuracy:
    outputs: tuple                  # OutputTol ...
    probe: float | None = None      # s; None: default window (probe_window)
    models: tuple | None = None     # None: admissible models up to the scene's
    elements: tuple = DEFAULT_ELEMENTS
    wraps: tuple = ("W0", "W1")
    steps: tuple | None = None      # s; None: output interval / (1, 2, 4, 8)
    margin: float = DEFAULT_MARGIN
    search: str = "first"           # first: stop at the first cost level that passes; all: run every rung
    full_check: bool = True         # verify the choice over the whole run against its next rung


def default_mode(name: str) -> str:
    parts = name.split(".")
    quantity = parts[-2] if len(parts) > 2 and parts[-1] in AXES else parts[-1]
    return "abs" if quantity in ABS_QUANTITIES else "rel"


def _number_list(r: _Reader, d, key, *, integer=False):
    path = f"accuracy.{key}"
    v = d[key]
    ok = isinstance(v, list) and v and all(
        not isinstance(x, bool) and isinstance(x, int if integer else (int, float)) for x in v)
    if not ok or not all(math.isfinite(x) and x > 0 for x in v):
        r.fail(path, f"must be a non-empty list of positive {'integers' if integer else 'numbers'}, got {v!r}")
    return tuple(sorted(set(int(x) if integer else float(x) for x in v)))


def parse_accuracy(raw: dict, source: str) -> Accuracy:
    """Validate an [accuracy] table (scene file, possibly merged with command-line values). Errors are
    SceneError naming the source and the key path, like every other scene error."""
    r = _Reader(source)
    r.table(raw, "accuracy", ACCURACY_KEYS)
    outs = raw.get("outputs")
    if outs is None:
        r.fail("accuracy", "missing required key 'outputs' (list of output names, e.g. [\"car.position\"]; "
                           "or --accuracy-outputs)")
    if not isinstance(outs, list) or not outs or not all(isinstance(o, str) and o for o in outs):
        r.fail("accuracy.outputs", f"must be a non-empty list of output names, got {outs!r}")
    if len(set(outs)) != len(outs):
        r.fail("accuracy.outputs", f"duplicate output names in {outs!r}")
    tol = r.number(raw, "accuracy", "tol", None, positive=True)
    tols = raw.get("tols", {})
    if not isinstance(tols, dict):
        r.fail("accuracy.tols", f"must be a table {{ \"<output>\" = tol or {{ abs = x }} or {{ rel = x }} }}, "
                                f"got {tols!r}")
    per = {}
    for name, spec in tols.items():
        path = f"accuracy.tols.{name}"
        if name not in outs:
            r.fail(path, f"{name!r} is not in accuracy.outputs {outs!r}")
        if isinstance(spec, dict):
            r.table(spec, path, {"abs", "rel"})
            if len(spec) != 1:
                r.fail(path, "give exactly one of 'abs' or 'rel'")
            mode = next(iter(spec))
            per[name] = (mode, r.number(spec, path, mode, positive=True))
        else:
            per[name] = (default_mode(name), r.number(tols, "accuracy.tols", name, positive=True))
    outputs = []
    for i, name in enumerate(outs):
        if name in per:
            outputs.append(OutputTol(name, *per[name]))
        elif tol is None:
            r.fail("accuracy", f"missing required key 'tol' (no tolerance for accuracy.outputs[{i}] {name!r}; "
                               f"or --accuracy-tol)")
        else:
            outputs.append(OutputTol(name, default_mode(name), tol))
    models = None
    if "models" in raw:
        models = raw["models"]
        if not isinstance(models, list) or not models or not all(m in DYNAMIC_MODELS for m in models):
            r.fail("accuracy.models", f"must be a non-empty list from {', '.join(map(repr, DYNAMIC_MODELS))}, "
                                      f"got {models!r}")
        models = tuple(sorted(set(models), key=MODEL_RANK.get))
    wraps = ("W0", "W1")
    if "wraps" in raw:
        wraps = raw["wraps"]
        if not isinstance(wraps, list) or not wraps or not all(w in ("W0", "W1") for w in wraps):
            r.fail("accuracy.wraps", f"must be a non-empty list from 'W0', 'W1', got {wraps!r}")
        wraps = tuple(sorted(set(wraps)))
    return Accuracy(
        outputs=tuple(outputs),
        probe=r.number(raw, "accuracy", "probe", None, positive=True),
        models=models,
        elements=_number_list(r, raw, "elements", integer=True) if "elements" in raw else DEFAULT_ELEMENTS,
        wraps=wraps,
        steps=_number_list(r, raw, "steps") if "steps" in raw else None,
        margin=r.number(raw, "accuracy", "margin", DEFAULT_MARGIN, positive=True),
        search=r.string(raw, "accuracy", "search", "first", ("first", "all")),
        full_check=r.boolean(raw, "accuracy", "full_check", True),
    )


def accuracy_for(scene: Scene, outputs=None, tol=None) -> Accuracy | None:
    """The scene's [accuracy] with command-line values (outputs list, tol) taking precedence; None when
    neither asks for a selection."""
    raw = dict(scene.extra.get("accuracy", {}) or {})
    if outputs is not None:
        raw["outputs"] = list(outputs)
    if tol is not None:
        raw["tol"] = tol
    if not raw:
        return None
    cli = outputs is not None or tol is not None
    return parse_accuracy(raw, scene.source + (" with --accuracy-* options" if cli else ""))


# ------------------------------------------------------------------------------------ candidates
@dataclass(frozen=True, order=True)
class Config:
    model: str
    elements: int         # per free span, every rope
    wrap: str             # W0 | W1
    step: float           # s, generalized-alpha step

    def label(self) -> str:
        return f"{self.model} n={self.elements} {self.wrap} h={self.step * 1e3:g} ms"

    def as_dict(self) -> dict:
        return dict(model=self.model, elements_per_span=self.elements, wrap_model=self.wrap, step=self.step)


def configure(scene: Scene, cfg: Config) -> Scene:
    """The scene with the configuration applied (a new Scene)."""
    ropes = tuple(replace(rp, elements_per_span=cfg.elements, wrap_model=cfg.wrap) for rp in scene.ropes)
    return replace(scene, model=cfg.model, ropes=ropes, solver=replace(scene.solver, step=cfg.step))


def _world_y(scene: Scene):
    """y of every sheave centre and rope anchor at t = 0."""
    pos = {b.name: b.position for b in scene.bodies}
    ys = [sh.center[1] + (pos[sh.body][1] if sh.body else 0.0) for sh in scene.sheaves]
    for rp in scene.ropes:
        for st in rp.route:
            if st.sheave is None:
                ys.append(st.at[1] + (pos[st.anchor][1] if st.anchor != "ground" else 0.0))
    return ys


def model_limits(scene: Scene) -> dict:
    """Model name -> None if it can represent the scene, else why not."""
    ys = _world_y(scene)
    coplanar = None
    if any(abs(abs(sh.axis[1]) - 1.0) > 1e-9 for sh in scene.sheaves):
        coplanar = "a sheave axis is not along y (non-coplanar reeving)"
    elif any("y" in b.free for b in scene.bodies):
        coplanar = "a body is free in y"
    elif ys and max(ys) - min(ys) > 1e-9:
        coplanar = "sheaves and anchors are not in one x-z plane"
    one_d = coplanar
    if one_d is None and any(len(b.free) > 1 for b in scene.bodies):
        one_d = "a body has more than one free axis (it swings)"
    if one_d is None and scene.ropes[0].element == "cubic":
        one_d = "cubic (bending) rope elements need a planar or spatial model"
    return {"axial-1d": one_d, "planar": coplanar, "spatial": None}


def candidate_models(scene: Scene, acc: Accuracy) -> tuple:
    limits = model_limits(scene)
    if acc.models is None:   # the scene's model is the ceiling; cheaper models where they fit
        return tuple(m for m in DYNAMIC_MODELS
                     if m == scene.model or (MODEL_RANK[m] < MODEL_RANK[scene.model] and limits[m] is None))
    for i, m in enumerate(acc.models):
        if limits[m] is not None and m != scene.model:
            raise SceneError(f"{scene.source}: [accuracy.models[{i}]] {m!r} cannot represent this scene: {limits[m]}")
    return acc.models


def has_wraps(scene: Scene) -> bool:
    return any(len(rp.route) > 2 for rp in scene.ropes)


def probe_window(scene: Scene, t_end: float, probe: float | None = None):
    """(seconds, why) of the probe window, starting at t = 0."""
    if probe is not None:
        return min(probe, t_end), "set by accuracy.probe"
    dv = scene.drive
    if dv.kind == "speed" and dv.profile == "s-curve" and dv.distance != 0.0:
        from ..core.profiles import scurve_phases
        d, _ = scurve_phases(dv.distance, dv.v_max, dv.a_max, dv.jerk)
        t_acc = sum(d[:3])
        t = dv.t_start + t_acc + SETTLE
        why = (f"drive start {dv.t_start:g} s + jerk-limited acceleration {t_acc:.2f} s + {SETTLE:g} s "
               f"settling: the start excites the axial rope modes as the stop does, the cruise is "
               f"quasi-static")
    elif dv.kind == "speed" and dv.profile == "table" and dv.table:
        v = np.abs([p[1] for p in dv.table])
        t = dv.table[int(np.argmax(v))][0] + SETTLE
        why = f"speed table up to its peak speed + {SETTLE:g} s settling"
    else:
        t = OTHER_PROBE
        why = f"no S-curve drive: the first {OTHER_PROBE:g} s"
    if t >= t_end:
        return t_end, why + " (capped at the run's end: the probe is the whole run)"
    return t, why


def resolve_output(name: str, names) -> str | None:
    """`name` in a run's output names, across models: 'car.position' <-> 'car.position.z' for a body
    with one free axis."""
    if name in names:
        return name
    base, _, ax = name.rpartition(".")
    if ax in AXES and base in names:
        return base
    hits = [f"{name}.{a}" for a in AXES if f"{name}.{a}" in names]
    return hits[0] if len(hits) == 1 else None


# ------------------------------------------------------------------------------------- the probe
@dataclass
class Candidate:
    config: Config
    nq: int | None = None
    n_steps: int = 0
    cost: float | None = None           # nq * n_steps (deterministic proxy)
    wall: float | None = None           # s, measured (reported only)
    errors: dict = field(default_factory=dict)   # output -> direct: max |candidate - reference| [SI]
    bounds: dict = field(default_factory=dict)   # output -> axis bound (select) [SI]
    ratios: dict = field(default_factory=dict)   # output -> max(direct, bound) / tolerance
    full_check: dict = field(default_factory=dict)  # output -> full run |this - next rung| / tolerance
    full_next: str = ""                 # the next rung of the full-run check
    status: str = "not run"             # chosen | passed | rejected | failed | costlier | reference
    reason: str = ""

    @property
    def worst(self) -> float:
        return max(self.ratios.values()) if self.ratios else math.inf

    def as_dict(self) -> dict:
        return dict(config=self.config.as_dict(), label=self.config.label(), n_dof=self.nq, n_steps=self.n_steps,
                    cost=self.cost, wall_s=self.wall, errors=self.errors, bounds=self.bounds,
                    estimate_over_tol=self.ratios, full_run_check_over_tol=self.full_check,
                    full_run_check_against=self.full_next,
                    status=self.status, reason=self.reason)


def _steps_per_output(out_dt: float, h: float) -> int:
    return max(1, math.ceil(out_dt / h - 1e-9))       # as Simulator.advance


def _prepare(scene: Scene, cand: Candidate, n_out: int, out_dt: float):
    """Build the candidate's model (nq and cost); a scene the configuration cannot build -> failed."""
    from ..core.model import build_model
    from ..core.solver import SolverError
    from ..core.geometry import GeometryError
    try:
        model = build_model(configure(scene, cand.config))
    except (SceneError, SolverError, GeometryError, ValueError) as exc:
        cand.status, cand.reason = "failed", f"cannot build: {exc}"
        return None
    cand.nq = model.nq
    cand.n_steps = n_out * _steps_per_output(out_dt, cand.config.step)
    cand.cost = float(cand.nq * cand.n_steps)
    return model


def _run(model, cand: Candidate, t_probe: float, out_dt: float):
    """Probe run; the result columns or None (cand marked failed)."""
    from ..core.solver import Simulator, SolverError
    t0 = time.perf_counter()
    try:
        res = Simulator(model, method="gen-alpha", step=cand.config.step).run(t_probe, out_dt)
    except (SolverError, ValueError, np.linalg.LinAlgError) as exc:
        cand.wall = time.perf_counter() - t0
        cand.status, cand.reason = "failed", f"probe run failed: {exc}"
        return None
    cand.wall = time.perf_counter() - t0
    return res


def _columns(res, outputs) -> dict:
    return {o.name: np.asarray(res[resolve_output(o.name, res.names)], float) for o in outputs}


def _diff(a: dict, b: dict) -> dict:
    return {n: float(np.max(np.abs(a[n] - b[n]))) for n in a}


def _rejection(cand: Candidate, margin: float) -> str:
    bad = [f"{n} {cand.ratios[n]:.3g} tol" for n, r in cand.ratios.items() if r > margin]
    what = "estimate" if cand.errors else "axis bound (not run)"
    return f"{what} above {margin:g} tol: " + ", ".join(bad)


# ------------------------------------------------------------------------------------- selection
@dataclass
class Report:
    scene: str
    outputs: list                      # dicts: name, mode, tol, peak, allowed (SI)
    probe: float
    probe_why: str
    out_dt: float
    t_end: float
    margin: float
    search: str
    models: tuple
    reference: Candidate
    finest: Candidate
    reliable: bool
    reliability: str
    candidates: list                   # Candidate, cost order
    chosen: Candidate
    why: str
    wall_total: float
    notes: list = field(default_factory=list)
    chosen_result: object = None       # the chosen configuration's full run (solver Result), if made

    def as_dict(self) -> dict:
        return dict(scene=self.scene, outputs=self.outputs, probe_s=self.probe, probe_why=self.probe_why,
                    output_step_s=self.out_dt, t_end_s=self.t_end, margin=self.margin, search=self.search,
                    models=list(self.models), reference=self.reference.as_dict(),
                    finest_candidate=self.finest.config.label(), reliable=self.reliable,
                    reliability=self.reliability, chosen=self.chosen.config.as_dict(),
                    chosen_label=self.chosen.config.label(), why=self.why,
                    probe_wall_total_s=self.wall_total, notes=self.notes,
                    candidates=[c.as_dict() for c in self.candidates])

    def write_json(self, path):
        from pathlib import Path
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(self.as_dict(), indent=1, default=float) + "\n", encoding="utf-8")
        return path

    def text(self) -> str:
        tl = ", ".join(f"{o['name']} {o['allowed']:.3g} ({o['mode']} {o['tol']:g})" for o in self.outputs)
        lines = [f"fidelity selection for {self.scene}: tolerance {tl}",
                 f"  probe 0-{self.probe:g} s ({self.probe_why}), output grid {self.out_dt * 1e3:g} ms; "
                 f"pass if estimate <= {self.margin:g} tol",
                 f"  reference {self.reference.config.label()} ({self.reference.nq} dof, "
                 f"{self.reference.wall:.2f} s); {self.reliability}"]
        names = [o["name"] for o in self.outputs]
        lines.append(f"  estimate / tol = max(direct error, axis bound) / tol")
        lines.append(f"  {'candidate':<34} {'dof':>4} {'cost':>9} {'wall s':>7}  "
                     + "  ".join(f"{n[:22]:>22}" for n in names) + "  status")
        skipped = [c for c in self.candidates if c.status == "costlier"]
        for c in self.candidates:
            if c.status == "costlier":
                continue
            errs = "  ".join(f"{c.ratios[n]:>17.3g} tol" if n in c.ratios else f"{'-':>22}" for n in names)
            cost = f"{c.cost:9.3g}" if c.cost is not None else f"{'-':>9}"
            wall = f"{c.wall:7.2f}" if c.wall is not None else f"{'-':>7}"
            lines.append(f"  {c.config.label():<34} {c.nq if c.nq is not None else '-':>4} {cost} {wall}  "
                         f"{errs}  {c.status}{': ' + c.reason if c.status != 'chosen' else ''}")
        if skipped:
            lines.append(f"  ({len(skipped)} costlier candidates within the tolerance not shown; see the JSON report)")
        lines.append(f"  chosen: {self.chosen.config.label()} - {self.why}")
        lines += [f"  note: {n}" for n in self.notes]
        lines.append(f"  probe runs and full-run checks took {self.wall_total:.2f} s in total")
        return "\n".join(lines)


def select(scene: Scene, acc: Accuracy, t_end: float | None = None, out_dt: float | None = None,
           step: float | None = None, log=None) -> Report:
    """Run the probe ladder and choose. `step` fixes the step (the ladder then varies the rest);
    t_end/out_dt are the full run's (default: the scene's). Raises SceneError (bad [accuracy]) or
    FidelityError (the reference configuration cannot run).

    The steps (docs/fidelity.md, "How the choice is made"), each a method of `_Selection`: check the
    outputs against the scene; build the ladder; run the reference and set the allowed error per
    output; run the finest candidate and the axis runs and give every candidate its estimate; take
    the candidates in cost order until one passes (and passes the full-run check); label the rest."""
    t_end = scene.t_end if t_end is None else t_end
    out_dt = scene.output_step if out_dt is None else out_dt
    if scene.solver.method != "gen-alpha":
        raise SceneError(f"{scene.source}: [solver.method] fidelity selection chooses the generalized-alpha "
                         f"step; the scene uses {scene.solver.method!r} (set 'gen-alpha' or run with --no-fidelity)")
    sel = _Selection(scene, acc, t_end, out_dt, log)
    sel.check_outputs()
    sel.build_ladder(step)
    sel.wall0 = time.perf_counter()
    sel.run_reference()
    sel.prepare_candidates()
    sel.estimate()
    chosen, why = sel.choose()
    sel.label_the_rest(chosen)
    if not sel.reliable:
        sel.notes.append("the estimate is unreliable: refine the ladder (accuracy.elements/steps) or loosen tol")
    return Report(scene=scene.name, outputs=sel.outs, probe=sel.t_probe, probe_why=sel.why_probe, out_dt=out_dt,
                  t_end=t_end, margin=acc.margin, search=acc.search, models=sel.models, reference=sel.ref,
                  finest=sel.finest, reliable=sel.reliable, reliability=sel.reliability, candidates=sel.cands,
                  chosen=chosen, why=why, wall_total=time.perf_counter() - sel.wall0, notes=sel.notes,
                  chosen_result=sel.full_runs.get(chosen.config, (None,))[0])


class _Selection:
    """State shared by the steps of `select`."""

    def __init__(self, scene: Scene, acc: Accuracy, t_end: float, out_dt: float, log):
        self.scene, self.acc, self.t_end, self.out_dt, self.log = scene, acc, t_end, out_dt, log
        self.src = scene.source
        self.models = candidate_models(scene, acc)
        self.notes = []
        self.runs = {}        # config -> output columns of its probe run (None: failed)
        self.full_runs = {}   # config -> (Result, columns) of its full run, or (None, error text)

    def say(self, msg):
        if self.log is not None:
            self.log(msg)

    def check_outputs(self):
        """Output names, checked against the scene as written."""
        from ..core.model import build_model
        try:
            base_names = build_model(self.scene).output_names
        except SceneError:
            base_names = ()
        for i, o in enumerate(self.acc.outputs):
            if base_names and resolve_output(o.name, base_names) is None:
                raise SceneError(f"{self.src}: [accuracy.outputs[{i}]] unknown output {o.name!r}; this scene "
                                 f"has: {', '.join(base_names)}")

    def build_ladder(self, step):
        """Every combination of model, elements, wrap and step; the reference (one refinement beyond
        the finest on every axis), the finest candidate, and the probe window."""
        scene, acc, out_dt, src = self.scene, self.acc, self.out_dt, self.src
        if step is not None:
            steps = (float(step),)
        elif acc.steps is not None:
            steps = acc.steps
        else:
            steps = tuple(out_dt / k for k in DEFAULT_STEP_DIVISORS)
        too_big = [h for h in steps if h > out_dt * (1 + 1e-9)]
        if too_big:
            raise SceneError(f"{src}: [accuracy.steps] {', '.join(f'{h:g}' for h in too_big)} s exceed the output "
                             f"interval {out_dt:g} s: outputs are sampled at step ends, so the run would shorten "
                             f"them (raise the output interval, e.g. --dt {max(too_big):g})")
        wraps = acc.wraps if has_wraps(scene) else (scene.ropes[0].wrap_model,)
        if not has_wraps(scene):
            self.notes.append("no sheave wraps in this scene: the wrap model does not matter")
        elems = acc.elements
        models = self.models
        self.ladder = [Config(m, n, w, h) for m, n, w, h in itertools.product(models, elems, wraps, steps)]
        self.ref_cfg = Config(models[-1], 2 * max(elems), "W1", min(steps) / 2)
        self.fin_cfg = Config(models[-1], max(elems), "W1" if "W1" in wraps else wraps[-1], min(steps))
        self.axes = {"model": models, "elements": elems, "wrap": wraps, "step": steps}
        t_probe, self.why_probe = probe_window(scene, self.t_end, acc.probe)
        self.n_out = max(1, int(round(t_probe / out_dt)))
        self.t_probe = self.n_out * out_dt

    def run_reference(self):
        """The reference probe run; the allowed error per output (absolute, or relative to the peak
        in the reference run)."""
        ref_cfg, t_probe, out_dt = self.ref_cfg, self.t_probe, self.out_dt
        ref = Candidate(ref_cfg)
        ref_model = _prepare(self.scene, ref, self.n_out, out_dt)
        self.say(f"fidelity: reference {ref_cfg.label()} over 0-{t_probe:g} s ...")
        res = _run(ref_model, ref, t_probe, out_dt) if ref_model is not None else None
        if res is None:
            raise FidelityError(f"{self.src}: fidelity reference {ref_cfg.label()} failed ({ref.reason}); restrict "
                                f"[accuracy] models/elements/steps")
        ref.status, ref.reason = "reference", "one refinement beyond the finest candidate in every axis"
        self.ref = ref
        self.ref_cols = ref_cols = _columns(res, self.acc.outputs)
        outs, allowed = [], {}
        for o in self.acc.outputs:
            peak = float(np.max(np.abs(ref_cols[o.name])))
            allowed[o.name] = o.tol if o.mode == "abs" else o.tol * peak
            if allowed[o.name] <= 0.0:
                allowed[o.name] = math.ulp(1.0)
                self.notes.append(f"{o.name} is zero throughout the probe: its relative tolerance is void")
            outs.append(dict(name=o.name, mode=o.mode, tol=o.tol, peak=peak, allowed=allowed[o.name],
                             unit_note="SI" if o.mode == "abs" else "fraction of peak |value|"))
        self.outs, self.allowed = outs, allowed

    def prepare_candidates(self):
        """Build every candidate's model (its cost needs the dof count) and sort by cost."""
        self.cands = cands = [Candidate(c) for c in self.ladder]
        self.by_cfg = {c.config: c for c in cands}
        self.prepared = {c.config: _prepare(self.scene, c, self.n_out, self.out_dt) for c in cands}
        cands.sort(key=self.order)

    _RANK_W = {w: i for i, w in enumerate(("W1", "W0"))}

    def order(self, c: Candidate):
        return (c.cost if c.cost is not None else math.inf, MODEL_RANK[c.config.model], -c.config.step,
                c.config.elements, self._RANK_W[c.config.wrap])

    def probe(self, cfg: Config):
        """The probe run of a configuration (cached), its error against the reference recorded."""
        runs = self.runs
        if cfg not in runs:
            c = self.by_cfg[cfg]
            runs[cfg] = None
            if self.prepared[cfg] is not None:
                self.say(f"fidelity: probe {cfg.label()} ...")
                r = _run(self.prepared[cfg], c, self.t_probe, self.out_dt)
                if r is not None:
                    runs[cfg] = _columns(r, self.acc.outputs)
                    c.errors = _diff(runs[cfg], self.ref_cols)
        return runs[cfg]

    def estimate(self):
        """The finest candidate and the axis runs (the finest with one axis set to each of its rungs);
        then per candidate the axis bound and the estimate."""
        acc, allowed, fin_cfg = self.acc, self.allowed, self.fin_cfg
        finest = self.by_cfg[fin_cfg]
        fin_cols = self.probe(fin_cfg)
        if fin_cols is None:
            raise FidelityError(f"{self.src}: the finest candidate {fin_cfg.label()} failed ({finest.reason}); "
                                f"restrict [accuracy] models/elements/steps")
        worst_name = max(acc.outputs, key=lambda o: finest.errors[o.name] / allowed[o.name]).name
        fin_ratio = finest.errors[worst_name] / allowed[worst_name]
        self.finest = finest
        self.reliable = reliable = fin_ratio <= RELIABLE
        self.reliability = (f"finest candidate vs reference: {fin_ratio:.3g} tol on {worst_name} "
                            f"({'<=' if reliable else '>'} {RELIABLE:g} tol: "
                            + ("the reference is converged enough)" if reliable else
                               "ESTIMATE UNRELIABLE, the reference is not converged)"))
        axis_dev = {}   # (axis, value) -> {output: max |axis run - finest|} or None (run failed)
        for ax, values in self.axes.items():
            for v in values:
                cols = self.probe(replace(fin_cfg, **{ax: v}))
                axis_dev[ax, v] = None if cols is None else _diff(cols, fin_cols)

        # Estimate = max(direct error, axis bound). The bound |finest - ref| + sum over axes of
        # |finest with this candidate's rung - finest| does not credit a cancellation of space and time
        # errors that holds at one rope length and not at another (docs/fidelity.md).
        for c in self.cands:
            devs = [axis_dev[ax, getattr(c.config, ax)] for ax in self.axes]
            if c.status == "failed" or any(d is None for d in devs):
                c.status = "failed"
                c.reason = c.reason or "an axis run with one of its rungs failed: no estimate"
                continue
            c.bounds = {o.name: finest.errors[o.name] + sum(d[o.name] for d in devs) for o in acc.outputs}
            c.ratios = {n: max(b, c.errors.get(n, 0.0)) / allowed[n] for n, b in c.bounds.items()}

    def evaluate(self, c: Candidate):
        """Pass or reject one candidate: by its bound alone if that fails, else after its probe run."""
        margin = self.acc.margin
        if c.status == "failed" or c.status in ("passed", "rejected"):
            return
        if c.worst > margin:        # the bound alone rejects it: no run needed
            c.status, c.reason = "rejected", _rejection(c, margin)
            return
        if self.probe(c.config) is None:
            c.status = "failed"
            return
        c.ratios = {n: max(b, c.errors[n]) / self.allowed[n] for n, b in c.bounds.items()}
        if c.worst <= margin:
            c.status, c.reason = "passed", ""
        else:
            c.status, c.reason = "rejected", _rejection(c, margin)

    def full(self, cfg: Config):
        """The full run of a configuration (cached)."""
        full_runs = self.full_runs
        if cfg not in full_runs:
            from ..core.solver import Simulator, SolverError
            from ..core.model import build_model
            self.say(f"fidelity: full-run check {cfg.label()} over 0-{self.n_full * self.out_dt:g} s ...")
            try:
                res = Simulator(build_model(configure(self.scene, cfg)), method="gen-alpha",
                                step=cfg.step).run(self.n_full * self.out_dt, self.out_dt)
                full_runs[cfg] = (res, _columns(res, self.acc.outputs))
            except (SceneError, SolverError, ValueError, np.linalg.LinAlgError) as exc:
                full_runs[cfg] = (None, str(exc))
        return full_runs[cfg]

    def full_check(self, c: Candidate) -> bool:
        """The candidate against its next rung (2 x elements, half the step, W1) over the whole run."""
        acc, n_full, out_dt = self.acc, self.n_full, self.out_dt
        nxt = Config(c.config.model, 2 * c.config.elements, "W1", c.config.step / 2)
        (_, a), (_, b) = self.full(c.config), self.full(nxt)
        if isinstance(a, str) or isinstance(b, str):
            c.status, c.reason = "rejected", f"full-run check failed to run: {a if isinstance(a, str) else b}"
            return False
        d = _diff(a, b)
        lim = {o.name: o.tol if o.mode == "abs" else o.tol * float(np.max(np.abs(b[o.name])))
               for o in acc.outputs}
        c.full_check = {n: d[n] / lim[n] for n in d}
        c.full_next = nxt.label()
        bad = [f"{n} {r:.3g} tol" for n, r in c.full_check.items() if r > acc.margin]
        if bad:
            c.status, c.reason = "rejected", (f"full-run check: differs from the next rung {nxt.label()} by "
                                              + ", ".join(bad) + f" > {acc.margin:g} tol over 0-{n_full * out_dt:g} s")
            return False
        return True

    def choose(self):
        """Cost order, one cost level at a time; a passing candidate must then pass the full-run
        check. Without any: the reference. Returns (chosen, why)."""
        acc, cands, ref = self.acc, self.cands, self.ref
        levels = [list(g) for _, g in itertools.groupby(cands, key=lambda c: c.cost)]
        if acc.search == "all":
            for c in cands:
                self.evaluate(c)
        self.n_full = max(1, int(round(self.t_end / self.out_dt)))
        chosen = None
        for level in levels:
            for c in level:
                self.evaluate(c)
            for c in sorted((c for c in level if c.status == "passed"), key=lambda c: (c.worst, self.order(c))):
                if not acc.full_check or self.full_check(c):
                    chosen = c
                    break
            if chosen is not None:
                break
        if chosen is None:
            chosen = ref
            ref.status = "chosen"
            why = (f"no candidate met {acc.margin:g} tol on every output; running the reference configuration "
                   f"(its own error is not estimated beyond the reliability check)")
        else:
            cheaper = [c for c in cands if c.cost is not None and c.cost < chosen.cost]
            why = (f"cheapest candidate (cost {chosen.cost:.3g} = {chosen.nq} dof x {chosen.n_steps} steps) whose "
                   f"estimate meets {acc.margin:g} tol on every output (worst {chosen.worst:.3g} tol); "
                   f"{len(cheaper)} cheaper candidate(s) rejected or failed"
                   + (f"; full-run check vs {chosen.full_next}: {max(chosen.full_check.values()):.3g} tol"
                      if chosen.full_check else ""))
        return chosen, why

    def label_the_rest(self, chosen: Candidate):
        """Status and reason of every candidate for the report."""
        margin, ref = self.acc.margin, self.ref
        for c in self.cands:
            if c is chosen:
                c.status, c.reason = "chosen", ""
            elif c.status == "passed" and c.cost <= chosen.cost and chosen is not ref:
                c.reason = ("meets the tolerance, costlier than the chosen" if c.cost > chosen.cost else
                            f"meets the tolerance at the same cost, larger estimate ({c.worst:.3g} tol)")
            elif c.status not in ("rejected", "failed"):
                if c.worst > margin:
                    c.status, c.reason = "rejected", _rejection(c, margin)
                else:
                    c.status = "costlier"
                    c.reason = "costlier than the chosen" + ("" if c.errors else " (not run; axis bound passes)")
