"""The co-simulation master: units stepped together over a list of connections.

A *unit* has named real inputs and outputs and steps from t to t + h:

* `FmuUnit`: an FMU through fmpy (a reeve_fmu.fmu.runner.SlaveHandle). Per step one fmi2SetReal,
  fmi2DoStep and fmi2GetReal (FMI 3.0: fmi3SetFloat64, fmi3DoStep, fmi3GetFloat64) through fmpy's ctypes
  functions, with preallocated value-reference and value arrays; an FMU whose inputs all come from one
  other FMU reads them straight from that FMU's output buffer (no copy).
* `PlantUnit`, `DriveUnit`: reeve_fmu.components' Plant and ElectricDrive in this process (the
  monolithic reference, the HIL reference run): the same models the FMUs run, without FMI.

Connections are data: `("plant.motor.speed", "drive.motor.speed")`, source first; the unit's name is
the text before the first dot. Schemes: "gauss-seidel" steps the units in the order given, each with the
newest outputs of the others; "jacobi" gives every unit the outputs at t, then steps them all.

Early return (FMI 3.0): when FMU units were instantiated with earlyReturnAllowed (SlaveHandle
`early_return`), a communication step is made in pieces: when such an FMU ends its step early at an
event (earlyReturn, lastSuccessfulTime te), the units that were already stepped beyond te are set back
to their state at the piece's start (fmi3SetFMUState) and stepped to te with the inputs they had; the
units after it in the Gauss-Seidel order step to te; an FMU that asked for event handling goes through
Event Mode at te with the others' outputs at te; the piece from te then continues to the same
communication point. Without such a unit (every FMI 2.0 run) the loop is the plain one.

`run(units, connections, n=..., step=...)` makes the communication steps and returns a `MasterRun` (the
recorded rows per unit, the steps made, wall times); `MasterRun.series()` turns it into the one result
type, reeve_fmu.core.results.TimeSeries. The elevator (fmu.cosim), the crane (fmu.crane), the monolithic
reference and the HIL reference run (hil.runners) are callers of `run`.

This module imports only numpy (plus reeve_fmu) at import time: it is vendored into the FMUs.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from functools import partial
from typing import Callable, Mapping, Optional, Sequence

import numpy as np

SCHEMES = ("gauss-seidel", "jacobi")
STATUS = ("ok", "warning", "discard", "error", "fatal", "pending")


class CosimError(RuntimeError):
    """A co-simulation step failed; the message carries the FMU log. Raised by `cosimulate` after the
    FMUs are closed, with `result` (the TimeSeries up to the last good communication point) and `time`
    (the failed step's start) set; both are None for a failure before the first step."""
    result = None
    time = None


def time_grid(step: float, kind: str = "ns") -> Callable[[int], float]:
    """Communication points t_k. "ns": for a step that is a whole number of nanoseconds,
    t_k = (k * step_ns) / 1e9, the correctly rounded k*step (what libcosim passes: it counts time in
    integer nanoseconds), otherwise k * step; "multiply": k * step."""
    step_ns = round(step * 1e9)
    if kind == "ns" and step_ns >= 1 and abs(step_ns - step * 1e9) <= 1e-6 * step * 1e9:
        ns = float(step_ns)
        return lambda k: (k * ns) / 1e9
    if kind not in ("ns", "multiply"):
        raise ValueError(f"time grid must be 'ns' or 'multiply', got {kind!r}")
    return lambda k: k * step


def parse_connections(connections, units: Mapping[str, object]) -> list[tuple[str, str, str, str]]:
    """[(source unit, source variable, target unit, target variable)] from ("unit.var", "unit.var") pairs;
    raises ValueError naming an unknown unit or a target connected twice."""
    out, targets = [], set()
    for pair in connections:
        if len(pair) != 2:
            raise ValueError(f"connection {pair!r}: give (source, target) as 'unit.variable' strings")
        ends = []
        for end in pair:
            unit, _, var = str(end).partition(".")
            if unit not in units or not var:
                raise ValueError(f"connection {pair!r}: {end!r} names no unit of {sorted(units)} "
                                 f"('unit.variable')")
            ends += [unit, var]
        if (ends[2], ends[3]) in targets:
            raise ValueError(f"connection {pair!r}: {pair[1]} is connected twice")
        targets.add((ends[2], ends[3]))
        out.append(tuple(ends))
    return out


# ------------------------------------------------------------------------------------------------
# units
# ------------------------------------------------------------------------------------------------
class _FastReal:
    """A preallocated value-reference array + value buffer for one setReal/getReal call per step."""

    def __init__(self, handle, names: Sequence[str], buf=None):
        from fmpy.fmi2 import fmi2Real, fmi2ValueReference

        self.names = tuple(names)
        self.n = len(self.names)
        self.vr = (fmi2ValueReference * self.n)(*[handle.vr(n) for n in self.names])
        self.buf = buf if buf is not None else (fmi2Real * self.n)()
        self.view = np.ctypeslib.as_array(self.buf) if self.n or buf is not None else np.empty(0)


def _no_call() -> int:
    return 0


class FmuUnit:
    """An FMU (SlaveHandle, set up and initialized) as a unit of the master. FMI 3.0 with early return
    (the handle's `early_return`): `returns_early`; after each step `early` (earlyReturn), `reached`
    (the time the step ended at) and `event` (eventHandlingNeeded)."""

    def __init__(self, name: str, handle):
        self.name, self.handle = name, handle
        self.fmi3 = bool(getattr(handle, "fmi3", False))
        self.returns_early = bool(getattr(handle, "early_return", False))
        self._saved = None

    def has_output(self, var: str) -> bool:
        v = self.handle.variables.get(var)
        return v is not None and v.type in ("Real", "Float64") and not getattr(v, "dimensions", None)

    def bind_outputs(self, exchange: Sequence[str], record: Sequence[str]) -> None:
        """The output buffer (the exchanged outputs first, then the recorded ones) and its getReal."""
        h = self.handle
        names = list(exchange) + [r for r in record if r not in exchange]
        missing = [v for v in names if not self.has_output(v)]
        if missing:
            raise ValueError(f"{self.name} ({h.path.name}) has no Real variables {missing}")
        self.outp = _FastReal(h, names)
        self.out = self.outp.view
        f = h.fmu
        if self.fmi3:
            self.get = partial(f.dll.fmi3GetFloat64, f.component, self.outp.vr, self.outp.n, self.outp.buf,
                               self.outp.n)
            self._bind_step3()
        else:
            self.get = partial(f.dll.fmi2GetReal, f.component, self.outp.vr, self.outp.n, self.outp.buf)
            self.step = partial(f.dll.fmi2DoStep, f.component)
        self.record_names = self.outp.names
        self.row = self._row

    def bind_inputs(self, inputs: Sequence[str], source=None) -> None:
        """The input buffer and its setReal. `source`: the FmuUnit whose output buffer starts with exactly
        these inputs (setReal then reads it in place), else None (own buffer, filled by the master)."""
        h = self.handle
        missing = [v for v in inputs if v not in h.variables]
        if missing:
            raise ValueError(f"{self.name} ({h.path.name}) has no variables {missing}")
        self.inp = _FastReal(h, inputs, buf=source.outp.buf if source is not None else None)
        self.in_view = self.inp.view
        f = h.fmu
        if not self.inp.n:
            self.set = _no_call
        elif self.fmi3:
            self.set = partial(f.dll.fmi3SetFloat64, f.component, self.inp.vr, self.inp.n, self.inp.buf, self.inp.n)
        else:
            self.set = partial(f.dll.fmi2SetReal, f.component, self.inp.vr, self.inp.n, self.inp.buf)

    def _bind_step3(self):
        """fmi3DoStep with its out-arguments preallocated; `reached` and `event` after each step."""
        from ctypes import byref
        from fmpy.fmi3 import fmi3Boolean, fmi3Float64

        f = self.handle.fmu
        flags = [fmi3Boolean() for _ in range(3)]
        last = fmi3Float64()
        early = flags[2]
        call = partial(f.dll.fmi3DoStep, f.component)
        refs = [byref(x) for x in flags] + [byref(last)]
        self.reached, self.event, self.early = 0.0, False, False

        def step(t, h, flag):
            s = call(t, h, bool(flag), *refs)
            self.early = early.value
            self.reached = last.value if self.early else t + h
            self.event = flags[0].value
            return s
        self.step = step

    def save(self) -> None:
        """Keep the FMU's state (fmi3GetFMUState / fmi2GetFMUstate) to step back to."""
        h = self.handle
        if self._saved is not None:
            h.free_state(self._saved)
        self._saved = h.get_state()

    def restore(self) -> None:
        self.handle.set_state(self._saved)

    def event_mode(self, gather) -> None:
        """After a step that returned eventHandlingNeeded: Event Mode, the inputs set there (gathered
        from the others' outputs at the event), fmi3UpdateDiscreteStates, Step Mode."""
        f = self.handle.fmu
        f.enterEventMode()
        if gather is not None:
            gather()
        _check(self.set(), f"{self.name} setFloat64 (Event Mode)", [self], self.reached)
        while f.updateDiscreteStates()[0]:
            pass
        f.enterStepMode()

    def _row(self):
        return self.out

    def index(self, var: str) -> int:
        return self.outp.names.index(var)

    def log(self) -> str:
        return f"--- {self.handle.instance_name} log ---\n{self.handle.log_text()}" if self.handle.messages else ""


class _ModelUnit:
    """A model in this process. Subclasses set INPUTS (the inputs the model takes, in its order) with
    DEFAULTS (the value of an unconnected input), and implement `advance(t, h, inputs)` (returns the new
    `out`), `index(var)` (position in `out`) and `recorder(names)` (a function returning those values)."""
    INPUTS: tuple = ()
    DEFAULTS: tuple = ()

    def has_output(self, var: str) -> bool:
        return var in self.output_names

    def bind_outputs(self, exchange: Sequence[str], record: Sequence[str]) -> None:
        missing = [v for v in list(exchange) + list(record) if not self.has_output(v)]
        if missing:
            raise ValueError(f"{self.name} has no outputs {missing}")
        for v in exchange:
            self.index(v)
        self.set = self.get = _no_call
        self.record_names = tuple(record)
        self.row = self.recorder(self.record_names)

    def bind_inputs(self, inputs: Sequence[str], source=None) -> None:
        bad = [v for v in inputs if v not in self.INPUTS]
        if bad:
            raise ValueError(f"{self.name} takes the inputs {list(self.INPUTS)}, not {bad}")
        self.in_view = np.zeros(len(inputs))
        self._pos = [(list(inputs).index(v) if v in inputs else None, d) for v, d in zip(self.INPUTS, self.DEFAULTS)]

    def step(self, t: float, h: float, _flag: int = 1) -> int:
        u = self.in_view
        self.out = self.advance(t, h, [d if p is None else u[p] for p, d in self._pos])
        return 0

    def log(self) -> str:
        return ""


class PlantUnit(_ModelUnit):
    """components.plant.Plant: inputs motor.torque and brake.command held over the step; outputs the
    plant's (`out` is the plant's output vector)."""
    INPUTS = ("motor.torque", "brake.command")
    DEFAULTS = (0.0, 0.0)

    def __init__(self, name: str, plant, y0=None):
        self.name, self.plant = name, plant
        self.output_names = tuple(plant.output_names)
        self.out = plant._y if y0 is None else y0

    def index(self, var: str) -> int:
        if var not in self.output_names:
            raise ValueError(f"{self.name} has no output {var}")
        return self.output_names.index(var)

    def advance(self, t, h, u):
        return self.plant.step(h, u[0], u[1])

    def recorder(self, names):
        idx = [self.output_names.index(n) for n in names]
        return lambda: self.out[idx]


#: ElectricDrive outputs besides the step's results motor.torque and brake.command: name -> attribute
#: (an int: that component of `currents`)
DRIVE_OUTPUTS = {"car.position_ref": "position_ref", "car.velocity_ref": "velocity_ref",
                 "car.acceleration_ref": "acceleration_ref", "motor.speed_ref": "speed_ref",
                 "drive.torque_ref": "torque_ref", "motor.current_d": 0, "motor.current_q": 1}


class DriveUnit(_ModelUnit):
    """components.drive.ElectricDrive: inputs motor.speed, motor.angle (held from t) and car.position
    (the shaft information system, in process only); outputs motor.torque, brake.command (`out`) and
    DRIVE_OUTPUTS."""
    INPUTS = ("motor.speed", "motor.angle", "car.position")
    DEFAULTS = (0.0, 0.0, math.nan)

    def __init__(self, name: str, drive):
        self.name, self.drive = name, drive
        self.output_names = ("motor.torque", "brake.command") + tuple(DRIVE_OUTPUTS)
        self.out = (0.0, 0.0)

    def index(self, var: str) -> int:
        if var not in ("motor.torque", "brake.command"):
            raise ValueError(f"{self.name}: only motor.torque and brake.command can be connected, not {var}")
        return 0 if var == "motor.torque" else 1

    def advance(self, t, h, u):
        return self.drive.step(t, h, u[0], u[1], u[2])

    def recorder(self, names):
        d = self.drive

        def value(n):
            if n in ("motor.torque", "brake.command"):
                return self.out[0 if n == "motor.torque" else 1]
            a = DRIVE_OUTPUTS[n]
            return d.currents[a] if isinstance(a, int) else getattr(d, a)
        return lambda: [value(n) for n in names]


# ------------------------------------------------------------------------------------------------
# the run
# ------------------------------------------------------------------------------------------------
@dataclass
class MasterRun:
    """What `run` recorded: rows[unit] (row 0 at the start, then every `record_every` steps and at a
    stop) with the columns names[unit], the steps made and the walls."""
    names: dict
    rows: dict
    j: int                  # rows recorded
    n: int                  # steps made (fewer than asked if the probe stopped the run or a step failed)
    stop: bool              # stopped by the probe
    partial: bool           # the last row is the stop's, between two recording points
    step: float
    record_every: int
    t_first: float          # wall time of the first step (loads/compiles the units' kernels)
    loop_wall: float
    step_ns: Optional[dict] = None          # unit -> wall time of each doStep (ns), with timing=True
    failure: Optional[CosimError] = None    # the error that ended the run early, if any
    events: Optional[list] = None           # early return: [(time, unit)] of the steps ended at an event

    def drop_partial(self) -> None:
        """Keep only the rows at whole recording intervals."""
        if self.partial:
            self.j -= 1
            self.partial = False

    def times(self) -> np.ndarray:
        tt = np.arange(self.j) * (self.step * self.record_every)
        if self.partial:
            tt[-1] = self.n * self.step
        return tt

    def columns(self, record: Mapping[str, Sequence[str]]) -> dict:
        """{variable: recorded values} in the order of `record` ({unit: variables})."""
        return {v: self.rows[u][:self.j, self.names[u].index(v)] for u, vs in record.items() for v in vs}

    def series(self, record: Mapping[str, Sequence[str]], info: Optional[dict] = None):
        from ..core.results import TimeSeries

        return TimeSeries(self.times(), self.columns(record), info=dict(info or {}))


def _check(status, what, units, t):
    if status > 1:
        logs = "\n".join(x for x in (u.log() for u in units) if x)
        name = STATUS[status] if status < len(STATUS) else status
        raise CosimError(f"{what} at t = {t:.6f} s returned fmi2 status {status} ({name})\n{logs}")


def _bind(units, connections, record):
    """Bind every unit's outputs (exchanged first, then recorded) and inputs; returns the per-step plan
    [(unit, gather or None)] in the units' order."""
    by = {u.name: u for u in units}
    if len(by) != len(units):
        raise ValueError(f"unit names must differ: {[u.name for u in units]}")
    unknown = [u for u in record if u not in by]
    if unknown:
        raise ValueError(f"record names no unit {unknown} of {sorted(by)}")
    links = parse_connections(connections, by)
    exchange = {u: [] for u in by}
    inputs = {u: [] for u in by}
    for su, sv, tu, tv in links:
        if sv not in exchange[su]:
            exchange[su].append(sv)
        inputs[tu].append((tv, su, sv))
    for u in units:
        u.bind_outputs(exchange[u.name], list(record.get(u.name, ())))
    plan = []
    for u in units:
        src = {su for _, su, _ in inputs[u.name]}
        shared = None
        if len(src) == 1 and isinstance(u, FmuUnit) and isinstance(by[next(iter(src))], FmuUnit):
            s = by[next(iter(src))]
            if [sv for _, _, sv in inputs[u.name]] == list(s.outp.names[:len(inputs[u.name])]):
                shared = s
        u.bind_inputs([tv for tv, _, _ in inputs[u.name]], shared)
        gather = None
        if shared is None and inputs[u.name]:
            pairs = [(by[su], by[su].index(sv)) for _, su, sv in inputs[u.name]]
            gather = partial(_gather, u.in_view, pairs)
        plan.append((u, gather))
    return plan


def _gather(view, pairs):
    for i, (s, k) in enumerate(pairs):
        view[i] = s.out[k]


class _Timed:
    """A unit's call with the wall time of each call recorded (ns), one call per step."""

    def __init__(self, fn, n: int):
        self.fn, self.ns, self.k = fn, np.zeros(n, dtype=np.int64), 0

    def __call__(self, *args):
        a = time.perf_counter_ns()
        s = self.fn(*args)
        self.ns[self.k] = time.perf_counter_ns() - a
        self.k += 1
        return s


def run(units: Sequence, connections, *, n: int, step: float, scheme: str = "gauss-seidel", grid: str = "ns",
        record: Optional[Mapping[str, Sequence[str]]] = None, record_every: int = 1, probe=None,
        progress: Optional[Callable[[float], None]] = None, progress_every: float = 0.25, timing: bool = False,
        ns_step_differences: bool = False) -> MasterRun:
    """n communication steps of `step` seconds over `connections` (see the module docstring).

    units         FmuUnit/PlantUnit/DriveUnit objects; Gauss-Seidel steps them in this order
    grid          communication points (`time_grid`): "ns" (libcosim's) or "multiply" (k * step)
    record        {unit: outputs to record}: row 0 at the start, then every `record_every` steps
    probe         an object with start() (once, the units bound), before() and after(k) -> stop? (around
                  every step): the coupling monitor of fmu.cosim
    progress      called with the simulated time every `progress_every` s of simulated time and at the end
    timing        record the wall time of every setReal, doStep and getReal (MasterRun.step_ns)
    ns_step_differences   pass communicationStepSize = t_(k+1) - t_k of the time grid instead of `step`
                  (what libcosim does: for bit-for-bit comparisons with it)

    A failing FMU call (status discard or worse) ends the run; MasterRun.failure then holds the
    CosimError (with the FMUs' logs) and the rows recorded before it."""
    if not (step > 0.0 and math.isfinite(step)):
        raise ValueError(f"communication step must be a finite number > 0, got {step!r}")
    if scheme not in SCHEMES:
        raise ValueError(f"scheme must be 'gauss-seidel' or 'jacobi', got {scheme!r}")
    record = dict(record or {})
    record_every = max(1, int(record_every))
    plan = _bind(units, connections, record)
    for u, _ in plan:
        _check(u.get(), f"{u.name} getReal", units, 0.0)
    if probe is not None:
        probe.start()
    step_ns = None
    if timing:
        step_ns = {}
        for u, _ in plan:
            u.set, u.step, u.get = _Timed(u.set, n), _Timed(u.step, n), _Timed(u.get, n)
            step_ns[u.name] = {"set": u.set.ns, "step": u.step.ns, "get": u.get.ns}
    nrec = n // record_every + 1
    recs = [(u, np.empty((nrec, len(u.record_names)))) for u, _ in plan if u.name in record]
    for u, R in recs:
        R[0] = u.row()
    every = max(1, int(round(progress_every / step))) if progress is not None else n + 1
    run_ = MasterRun({u.name: u.record_names for u, _ in recs}, {u.name: R for u, R in recs}, 1, n, False,
                     False, step, record_every, 0.0, 0.0, step_ns)
    gs = scheme == "gauss-seidel"
    back = _early_plan(plan, gs)
    if not any(getattr(u, "returns_early", False) for u, _ in plan):
        _loop(run_, plan, units, time_grid(step, grid), ns_step_differences, gs, probe, recs, progress, every)
    elif timing or ns_step_differences:
        raise ValueError("timing and ns_step_differences are per communication step: not with early return")
    else:
        _loop_events(run_, plan, back, units, time_grid(step, grid), gs, probe, recs, progress, every)
    if progress is not None:
        progress(run_.n * step)
    return run_


def _early_plan(plan, gs: bool) -> list:
    """The units to save before each piece of a step, to set back when a unit ends its step early:
    Gauss-Seidel, those stepped before the last unit that may return early; Jacobi, all."""
    early = [i for i, (u, _) in enumerate(plan) if getattr(u, "returns_early", False)]
    if not early:
        return []
    back = [x for i, x in enumerate(plan) if not gs or i < early[-1]]
    bad = [u.name for u, _ in back if not hasattr(u, "save")]
    if bad:
        raise ValueError(f"early return: the units {bad} cannot be set back to an earlier state (FMU units can)")
    return back


def _end_of_step(k, j, stop, probe, recs, record_every, progress, every, step):
    """After communication step k: the probe's verdict, the record row j, the progress report; returns
    (the next row, stop)."""
    if probe is not None:
        stop = probe.after(k)
    if (k + 1) % record_every == 0 or stop:
        for u, R in recs:
            R[j] = u.row()
        j += 1
    if (k + 1) % every == 0:
        progress((k + 1) * step)
    return j, stop


def _loop(run_: MasterRun, plan, units, tk, ns_diff, gs, probe, recs, progress, every) -> None:
    """The communication steps: the master's whole per-step cost (docs/cosim.md, Performance); what the
    loop touches is bound to local names first."""
    n, step, record_every = run_.n, run_.step, run_.record_every
    # Gauss-Seidel: one unit after the other sets, steps and gets; Jacobi: all set, all step, all get
    groups = [[x] for x in plan] if gs else [plan]
    j, h, stop, t_first = 1, step, False, 0.0
    t_loop0 = time.perf_counter()
    k = 0
    try:
        for k in range(n):
            t = tk(k)
            if ns_diff:
                h = tk(k + 1) - t
            if probe is not None:
                probe.before()
            for group in groups:
                for u, gather in group:
                    if gather is not None:
                        gather()
                    s = u.set()
                    if s > 1:
                        _check(s, f"{u.name} setReal", units, t)
                for s, (u, _) in zip([u.step(t, h, 1) for u, _ in group], group):
                    if s > 1:
                        _check(s, f"{u.name} doStep", units, t)
                for u, _ in group:
                    s = u.get()
                    if s > 1:
                        _check(s, f"{u.name} getReal", units, t)
            j, stop = _end_of_step(k, j, stop, probe, recs, record_every, progress, every, step)
            if k == 0:                      # the first step loads/compiles the units' kernels (JIT)
                t_first = time.perf_counter() - t_loop0
            if stop:
                n = k + 1
                break
    except CosimError as exc:   # a failed step ends the run; what was recorded before it is kept
        run_.failure, n = exc, k
    run_.loop_wall = time.perf_counter() - t_loop0
    run_.j, run_.n, run_.stop, run_.t_first = j, n, stop, t_first
    run_.partial = stop and n % record_every != 0


def _loop_events(run_: MasterRun, plan, back, units, tk, gs, probe, recs, progress, every) -> None:
    """The communication steps with a unit that may return early (module docstring): each step from t_k
    to t_(k+1) in pieces (_piece); recording, probe and progress per communication step as in _loop."""
    n, step, record_every = run_.n, run_.step, run_.record_every
    groups = [[x] for x in plan] if gs else [plan]
    j, stop, t_first, events = 1, False, 0.0, []
    t_loop0 = time.perf_counter()
    k = 0
    try:
        for k in range(n):
            t, t_end = tk(k), tk(k + 1)
            if probe is not None:
                probe.before()
            h = step                    # a whole step is passed as `step`, as _loop does
            while t < t_end:
                t = _piece(groups, back, units, t, t_end, h, events)
                h = t_end - t
            j, stop = _end_of_step(k, j, stop, probe, recs, record_every, progress, every, step)
            if k == 0:
                t_first = time.perf_counter() - t_loop0
            if stop:
                n = k + 1
                break
    except CosimError as exc:
        run_.failure, n = exc, k
    run_.loop_wall = time.perf_counter() - t_loop0
    run_.j, run_.n, run_.stop, run_.t_first, run_.events = j, n, stop, t_first, events
    run_.partial = stop and n % record_every != 0


def _piece(groups, back, units, t, t_end, h, events) -> float:
    """Step every unit from t by h (to t_end), or to the earliest time te < t_end at which a unit that may
    return early ended its step at an event: the units already stepped beyond te (saved first: `back`)
    are set back and stepped to te with the inputs they had, those after it step to te; a unit that
    asked for event handling at te goes through Event Mode with the others' outputs at te. Returns the
    time reached."""
    for u, _ in back:
        u.save()
    te, done = t_end, []
    for group in groups:
        for u, gather in group:
            if gather is not None:
                gather()
            _ok(u.set(), u, "set", units, t)
        for u, _ in group:
            _ok(u.step(t, h if te == t_end else te - t, 1), u, "doStep", units, t)
        hits = [u for u, _ in group if getattr(u, "returns_early", False) and u.early and u.reached < te]
        if hits:
            hit = min(hits, key=lambda u: u.reached)
            te = hit.reached
            events.append((te, hit.name))
            for v, gather in done + [x for x in group if x[0] is not hit]:
                v.restore()
                if gather is not None:
                    gather()
                _ok(v.set(), v, "set", units, t)
                _ok(v.step(t, te - t, 1), v, "doStep (to the event)", units, t)
                if (v, gather) in done:
                    _ok(v.get(), v, "get", units, t)
        for u, _ in group:
            _ok(u.get(), u, "get", units, t)
        done += group
    for u, gather in done:
        if getattr(u, "returns_early", False) and u.early and u.event and u.reached == te:
            u.event_mode(gather)
    return te


def _ok(status, u, what, units, t) -> None:
    if status > 1:
        _check(status, f"{u.name} {what}", units, t)
