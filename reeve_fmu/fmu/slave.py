"""`ReeveSlave`: the pythonfmu base class every reeve_fmu FMU entry subclasses.

It adds to `pythonfmu.Fmi2Slave` (0.7.0) what the FMI standard, `fmpy validate` and robust masters need
and pythonfmu does not do (docs/cosim.md, 'pythonfmu and fmpy', items 1-3):

* declarative variables (reeve_fmu.fmu.description): `add_real/add_integer/add_boolean/add_string`
  with causality, variability, initial, unit (SI, with `UnitDefinitions` + `BaseUnit` exponents
  and display units such as rpm/mm), optional `declaredType` (TypeDefinitions), `derivative` relations, min/max, and explicit
  `ModelStructure` output dependencies (`dependencies=()` -> `dependencies=""`: the output is a pure
  function of the state, no algebraic loop). `InitialUnknowns` are generated consistently.
  Integer/Boolean default to `variability="discrete"`. The XML passes `fmpy validate` with no problems.
* values live in the plain dict `self.values` (name -> builtin scalar); subclass code reads inputs
  and writes outputs there (or passes `getter=` for computed outputs).
* honest FMU state (reeve_fmu.fmu.state): `get_hidden_state()/set_hidden_state()` hooks; the base snapshots *all* of it
  (registered values, time, mode, hidden state) as a canonical deep copy of builtin types, so an
  in-memory restore and a JSON (de)serialised restore are bit-identical. JSON keeps NaN/Inf.
* errors never escape into pythonfmu's C++ layer (there an exception becomes fmi2Fatal, loses its text
  and leaves a dangling instance): every method the C++ side calls is guarded; failures are logged with
  the full traceback through `self.log(..., Fmi2Status.error)` and `do_step` returns False
  (fmi2Discard). Invalid inputs (NaN/Inf, out of [min, max]), non-positive or non-finite step sizes,
  doStep outside step mode, time jumps and calls in the wrong state are rejected with a logged reason.
* `fmi2Reset`: pythonfmu 0.7.0 re-runs the class constructor (a brand-new Python object), so an
  instance comes back fresh as long as all mutable state lives on `self` (never in module or class
  globals). Verified by the machinery tests.

Subclass contract (see the example in tests/support/fmu_toy/reeve_toy_slave.py)::

    class MyPlant(ReeveSlave):
        description = "..."
        default_experiment = DefaultExperiment(start_time=0.0, stop_time=10.0, step_size=1e-3)

        def define(self):                 # declare variables (runs inside the constructor, guarded)
            self.add_real("motor.tau", "input", unit="N.m", start=0.0)
            self.add_real("sheave.w", "output", unit="rad/s", display_unit="rpm")
        def initialize(self):             # exitInitializationMode: build the model from parameters
        def step(self, t, dt) -> bool:    # one communication step; write outputs into self.values
                                          # (FMI 3.0, early_return_allowed: may return the float time
                                          # of an event inside the step instead, see might_return_early)
        def get_hidden_state(self) -> dict    # builtin types only (ndarray.tolist())
        def set_hidden_state(self, state)     # inverse of get_hidden_state

Do not override `__init__`/`do_step`/`set_real`/... (override the hooks instead), and never raise out
of them on purpose: return False from `step` after `self.log(reason, Fmi2Status.error)`.

Logging: pythonfmu alone forwards messages only when the master instantiates with loggingOn=True; the
FMU's native loader (reeve_fmu.fmu.native, Linux) always relays warnings and errors and OK messages
only with logging on. Messages are passed to the C logger as a printf *format*, so '%' is escaped
here.

Speed: `set_eager_outputs(names)` + `defer_outputs(write)` let step() write only the exchanged outputs
each step and the rest (from a snapshot) only when something reads them.
"""
from __future__ import annotations

import json
import math
import os
import sys
import traceback
from typing import Any, Callable, Iterable, Optional

from pythonfmu import Fmi2Slave
from pythonfmu.default_experiment import DefaultExperiment
from pythonfmu.enums import Fmi2Causality, Fmi2Status, Fmi2Variability

from . import fastlink
from ._bootstrap import STAMP_NAME, package_hash
from .description import _KINDS, Declarations, _Spec
from .state import FmuState

__all__ = ["ReeveSlave", "DefaultExperiment", "Fmi2Status"]

_package_hash_cache: dict[str, str] = {}


def _loaded_package_info() -> tuple[Optional[str], str, Optional[str]]:
    """(sha256, location, boot warning) of the reeve_fmu package imported in this process."""
    import reeve_fmu

    boot = getattr(reeve_fmu, "_reeve_fmu_boot", None) or {}
    location = os.path.dirname(os.path.abspath(reeve_fmu.__file__))
    if boot.get("hash") and boot.get("location") == location:
        return boot["hash"], location, boot.get("warning")
    if location not in _package_hash_cache:
        _package_hash_cache[location] = package_hash(location)
    return _package_hash_cache[location], location, boot.get("warning")


class ReeveSlave(Declarations, FmuState, Fmi2Slave):
    """Base class of reeve_fmu co-simulation slaves. See the module docstring for the contract."""

    #: class attribute or set in define() with set_default_experiment()
    default_experiment: Optional[DefaultExperiment] = None
    #: relative tolerance (of dt) for the check currentCommunicationPoint == end of the last step
    time_tolerance: float = 1e-6
    #: step() may end a step early at an event (FMI 3.0: mightReturnEarlyFromDoStep); it does so only
    #: after the host allowed it (allow_early_return, called by the FMI 3.0 adapter)
    might_return_early: bool = False

    # ------------------------------------------------------------------ construction
    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        # NB: Fmi2Slave.__init__ set an instance attribute default_experiment=None; drop it so the
        # class attribute (if any) is visible again.
        self.__dict__.pop("default_experiment", None)
        self.values: dict[str, Any] = {}
        self._specs: list[_Spec] = []
        self._by_name: dict[str, _Spec] = {}
        self._get = {k: {} for k in _KINDS}   # kind -> {vr: getter}
        self._set = {k: {} for k in _KINDS}   # kind -> {vr: spec} (settable variables only)
        self._real_names: list = []            # vr -> name of a Real kept in self.values (else None)
        self._user_setters: dict[str, Callable] = {}
        self._arrays: list = []                # FMI 3.0 array variables over declared scalars (add_array)
        self._fast_real: dict[int, tuple] = {}  # vr -> (name, lo, hi); non-empty only in step mode
        self._deferred: Optional[Callable] = None  # writes the outputs step() left for later
        self._eager_vrs: frozenset = frozenset()   # Reals step() always writes (see defer_outputs)
        self._link: Optional[fastlink.FastLink] = None  # tables shared with the native loader
        self._mode = "instantiated"
        self._initialized = False
        self.start_time: Optional[float] = None
        self.stop_time: Optional[float] = None
        self.tolerance: Optional[float] = None
        self.time: Optional[float] = None
        self._fault: Optional[str] = None      # sticky: define()/initialize() failed
        #: True once fmi2ExitInitializationMode failed (logged with its reason): pythonfmu 0.7.0 returns
        #: fmi2OK from it whatever Python does (an exception becomes fmi2Fatal and tears the instance
        #: down), so the FMU's native loader reads this after forwarding the call and returns fmi2Error
        self.initialization_failed = False
        self._dirty: Optional[str] = None      # step raised; needs setFMUstate or reset
        self._bad_inputs: dict[str, str] = {}  # name -> reason (value was rejected)
        self._pending: list[str] = []          # one-shot call errors, reported by the next doStep
        #: doSteps refused because of the call (wrong state or time, bad inputs, earlier call errors),
        #: not the model: the FMI 3.0 adapter returns fmi3Error for these, fmi3Discard otherwise
        self.refused_steps = 0
        #: the FMI 3.0 host instantiated with earlyReturnAllowed (never in FMI 2.0): step() may then
        #: return the time of an event inside the step instead of True
        self.early_return_allowed = False
        self.package_info: dict[str, Any] = {}
        if self.version is None:
            try:
                import reeve_fmu
                self.version = getattr(reeve_fmu, "__version__", None)
            except Exception:  # pragma: no cover
                pass
        try:
            self.define()
        except BaseException:
            self._fault = "define() failed:\n" + traceback.format_exc()
            self.log(self._fault, Fmi2Status.error)
        try:
            self._check_package_stamp()
        except Exception:
            self.log("reeve_fmu package stamp check failed:\n" + traceback.format_exc(),
                     Fmi2Status.warning)
        fastlink.offer(self)

    # ------------------------------------------------------------------ hooks (override these)
    def define(self) -> None:
        """Declare variables with add_real/add_integer/add_boolean/add_string."""

    def initialize(self) -> None:
        """Called in exitInitializationMode (parameters and start inputs are set): build the model."""

    def step(self, t: float, dt: float) -> bool:
        """Advance from t to t + dt. Return False (after logging why) if the step cannot be done."""
        raise NotImplementedError(f"{type(self).__name__}.step() is not implemented")

    def get_hidden_state(self) -> dict:
        """All state that is not in self.values, as builtin types (ndarray -> tolist())."""
        return {}

    def set_hidden_state(self, state: dict) -> None:
        """Restore what get_hidden_state() returned (receives a private deep copy)."""

    def on_terminate(self) -> None:
        """Called by fmi2Terminate."""

    def allow_early_return(self) -> None:
        """Called by the FMI 3.0 adapter when the host passed earlyReturnAllowed (and the model declares
        might_return_early): step() may from now on end a step at an event time."""
        self.early_return_allowed = bool(self.might_return_early)

    # ------------------------------------------------------------------ deferred outputs (speed)
    def set_eager_outputs(self, names: Iterable[str]) -> None:
        """The Real outputs step() writes into self.values on every step (typically what the master
        exchanges); all others may be left to `defer_outputs`."""
        self._eager_vrs = frozenset(self._by_name[n].vr for n in names)
        if self._link is not None:
            self._link.set_outputs(self._link_outputs())
            self._sync_link()

    def defer_outputs(self, write: Optional[Callable[[], None]]) -> None:
        """Called by step(): `write()` puts the remaining outputs into self.values. It runs only when
        something reads them (a getReal of another variable, getInteger/Boolean/String, getFMUstate),
        at most once per step, so a master that reads only the eager outputs never pays for it.
        `write` must use a snapshot taken in step() (the next step replaces it unrun), never live
        model state."""
        self._deferred = write

    # ------------------------------------------------------------------ the loader's fast path
    def _native_link(self) -> int:
        """Called once by the FMU's native loader: the address of the tables shared with it
        (reeve_fmu.fmu.fastlink), or 0 to decline (then every call goes through pythonfmu)."""
        try:
            if not fastlink.enabled() or self._fault is not None:
                return 0
            inputs = [(vr, s.name, s.min, s.max) for vr, s in self._set["Real"].items()
                      if s.causality == Fmi2Causality.input and s.name not in self._user_setters]
            link = fastlink.FastLink(len(self._specs), inputs, sys.float_info.max)
            link.set_outputs(self._link_outputs())
            self._link = link
            self._sync_link()
            return link.address
        except Exception:
            self._link = None
            self._error("the loader's fast path is off for this instance:\n" + traceback.format_exc(),
                        Fmi2Status.warning)
            return 0

    def _link_outputs(self) -> list:
        names = self._real_names
        return [(vr, names[vr]) for vr in sorted(self._eager_vrs)
                if names[vr] is not None and self._specs[vr].causality == Fmi2Causality.output]

    def _sync_link(self) -> None:
        """Tell the loader what it may do without Python (after any change of mode, rejected inputs or
        outputs outside do_step)."""
        link = self._link
        if link is None:
            return
        step = self._mode == "step"
        link.state[0] = 1 if step and not self._bad_inputs else 0
        link.state[1] = 1 if step and self._initialized and link.publish(self.values) else 0

    def _pull(self) -> None:
        link = self._link
        if link is not None and link.state[2]:
            link.pull(self.values)

    def _flush(self) -> None:
        write = self._deferred
        if write is not None:
            self._deferred = None
            write()

    def resource_path(self, name: str) -> str:
        """Absolute path of a file shipped with build_fmu(resources={name: ...})."""
        if not self.resources:
            raise FileNotFoundError(f"{name}: this instance has no resources directory")
        return os.path.join(self.resources, *name.split("/"))

    # ------------------------------------------------------------------ logging
    def log(self, msg: str, status: Fmi2Status = Fmi2Status.ok, category: Optional[str] = None,
            debug=None):
        # the C++ layer hands msg to the FMI logger as a printf format string
        super().log(str(msg).replace("%", "%%"), status, category)

    def _error(self, msg: str, status: Fmi2Status = Fmi2Status.error) -> None:
        try:
            self.log(f"[{self.instance_name}] {msg}", status)
        except Exception:  # pragma: no cover - logging must never raise into C++
            pass

    # ------------------------------------------------------------------ package stamp
    def _check_package_stamp(self) -> None:
        res = self.resources
        if not res:
            return
        path = os.path.join(res, STAMP_NAME)
        if not os.path.isfile(path):
            return
        with open(path, encoding="utf-8") as fh:
            stamp = json.load(fh)
        loaded, location, warning = _loaded_package_info()
        self.package_info = {"fmu_sha256": stamp.get("sha256"), "loaded_sha256": loaded,
                             "location": location, "fmu_version": stamp.get("version")}
        if warning:
            self.log(warning, Fmi2Status.warning)
        if stamp.get("sha256") != loaded:
            self.log(
                f"reeve_fmu version mismatch: this FMU was built from reeve_fmu sources "
                f"sha256={str(stamp.get('sha256'))[:16]} (version {stamp.get('version')}), but this "
                f"process had already imported reeve_fmu from {location} (sha256={str(loaded)[:16]}); "
                f"the FMU runs the already-imported code. Rebuild the FMU (reeve_fmu.fmu.build."
                f"fmu_is_stale) or load it in a process that has not imported reeve_fmu.",
                Fmi2Status.warning)

    # ------------------------------------------------------------------ lifecycle (called by C++)
    def setup_experiment(self, start_time: float = 0.0, stop_time: Optional[float] = None,
                         tolerance: Optional[float] = None):
        try:
            if self._mode != "instantiated":
                self._pending.append(f"setupExperiment called in state {self._mode!r}")
                self._error(self._pending[-1])
                return
            st = float(start_time)
            if not math.isfinite(st):
                self._pending.append(f"setupExperiment: start time {start_time!r} is not finite")
                self._error(self._pending[-1])
                return
            self.start_time = st
            self.stop_time = None if stop_time is None else float(stop_time)
            self.tolerance = None if tolerance is None else float(tolerance)
        except Exception:
            self._error("setup_experiment failed:\n" + traceback.format_exc())

    def enter_initialization_mode(self):
        try:
            if self._mode != "instantiated":
                self._pending.append(f"enterInitializationMode called in state {self._mode!r}")
                self._error(self._pending[-1])
                return
            self._set_mode("init")
        except Exception:  # pragma: no cover
            self._error("enter_initialization_mode failed:\n" + traceback.format_exc())

    def exit_initialization_mode(self):
        try:
            if self._mode != "init":
                self._pending.append(f"exitInitializationMode called in state {self._mode!r} "
                                     f"(expected after enterInitializationMode)")
                self._error(self._pending[-1])
                self.initialization_failed = True
                return
            if self.start_time is None:
                de = self.default_experiment
                self.start_time = float(de.start_time) if de is not None and de.start_time is not None else 0.0
            self.time = self.start_time
            self._set_mode("step")
            if self._fault is not None:
                self._error("cannot initialize, the instance is faulty:\n" + self._fault)
                self.initialization_failed = True
                return
            try:
                self.initialize()
                self._initialized = True
            except BaseException:
                self._fault = "initialize() failed:\n" + traceback.format_exc()
                self._error(self._fault)
                self.initialization_failed = True
            self._sync_link()
        except Exception:  # pragma: no cover
            self._error("exit_initialization_mode failed:\n" + traceback.format_exc())
            self.initialization_failed = True

    def terminate(self):
        try:
            self._set_mode("terminated")
            self.on_terminate()
        except Exception:
            self._error("terminate failed:\n" + traceback.format_exc())

    def do_step(self, current_time: float, step_size: float) -> bool:
        try:
            link = self._link
            if link is not None and link.state[2]:
                link.pull(self.values)
            if self._mode != "step" or self._fault or self._dirty or self._bad_inputs or self._pending:
                return self._refuse_step(current_time, step_size)
            t, dt, now = current_time, step_size, self.time
            # the usual case in one test: dt finite and > 0, t finite and where the FMU is
            if not (dt > 0.0 and dt - dt == 0.0 and t - t == 0.0 and (
                    t == now or now is None or abs(t - now) <= self.time_tolerance * dt + 1e-12 * abs(t))):
                return self._reject_step(t, dt, now)
            n_log = len(self.log_queue)
            try:
                ok = self.step(t, dt)
            except BaseException:  # incl. SystemExit/KeyboardInterrupt: never into pythonfmu's C++
                self._dirty = (f"step(t={t!r}, dt={dt!r}) raised:\n" + traceback.format_exc())
                self._error(self._dirty)
                self._sync_link()
                return False
            if link is not None:
                try:   # link.publish, inlined: the exchanged outputs into the loader's table
                    val, vals = link.val, self.values
                    for vr, name in link.outputs:
                        val[vr] = vals[name]
                except TypeError:
                    link.state[1] = 1 if link.publish(self.values) else 0
            if ok is False:
                if len(self.log_queue) == n_log:
                    self._error(f"step(t={t!r}, dt={dt!r}) returned False without logging a reason",
                                Fmi2Status.warning)
                return False
            if ok is not True and type(ok) is float:
                if self.early_return_allowed and t < ok < t + dt:
                    self.time = ok    # an early return at an event (step() logged the reason)
                    return True
                self._dirty = (f"step(t={t!r}, dt={dt!r}) returned the time {ok!r}: an early return needs "
                               f"earlyReturnAllowed (FMI 3.0) and a time inside the step")
                self._error(self._dirty)
                return False
            self.time = t + dt
            return True
        except Exception:  # pragma: no cover - belt and braces
            self._error("do_step failed:\n" + traceback.format_exc())
            return False

    def _reject_step(self, t, dt, now) -> bool:
        self.refused_steps += 1
        if not (dt > 0.0) or dt == math.inf:
            self._error(f"doStep rejected: communicationStepSize={dt!r} at t={t!r} (must be finite and > 0)")
        elif t - t != 0.0:
            self._error(f"doStep rejected: currentCommunicationPoint={t!r} is not finite")
        else:
            self._error(f"doStep rejected: currentCommunicationPoint={t!r} but the FMU is at "
                        f"t={now!r} (steps must be contiguous; use setFMUstate to go back)")
        return False

    def _refuse_step(self, t, dt) -> bool:
        self.refused_steps += 1
        if self._fault:
            self._error(f"doStep(t={t!r}) refused: the instance is faulty (reset or re-instantiate).\n"
                        + self._fault)
        elif self._mode != "step":
            hint = {"instantiated": "call setupExperiment/enterInitializationMode/"
                                    "exitInitializationMode first",
                    "init": "call exitInitializationMode first",
                    "terminated": "the instance was terminated"}.get(self._mode, "")
            self._error(f"doStep(t={t!r}) refused in state {self._mode!r}: {hint}")
        elif self._dirty:
            self._error(f"doStep(t={t!r}) refused: a previous step raised an exception and the state "
                        f"may be inconsistent; restore a state (fmi2SetFMUstate) or reset.\n"
                        + self._dirty.splitlines()[0])
        elif self._bad_inputs:
            reasons = "; ".join(f"{k}: {v}" for k, v in self._bad_inputs.items())
            self._error(f"doStep(t={t!r}) refused: invalid inputs were rejected ({reasons}); "
                        f"set valid values to continue")
        else:
            reasons = "; ".join(self._pending)
            self._pending.clear()
            self._error(f"doStep(t={t!r}) refused because of earlier call errors: {reasons}")
        return False

    # ------------------------------------------------------------------ getters / setters
    def _set_mode(self, mode: str) -> None:
        self._mode = mode
        fast = {}
        if mode == "step":
            for vr, spec in self._set["Real"].items():
                if spec.causality == Fmi2Causality.input and spec.name not in self._user_setters:
                    # +-DBL_MAX (not inf) so that +-inf falls through to the checked path
                    fast[vr] = (spec.name,
                                -sys.float_info.max if spec.min is None else float(spec.min),
                                sys.float_info.max if spec.max is None else float(spec.max))
        self._fast_real = fast
        self._sync_link()

    def _get_values(self, kind, vrs, conv, bad):
        g = self._get[kind]
        self._pull()
        try:
            self._flush()
            return [conv(g[vr]()) for vr in vrs]
        except Exception:
            out = []
            for vr in vrs:
                try:
                    out.append(conv(g[vr]()))
                except KeyError:
                    out.append(bad)
                    self._call_error(f"get{kind}: value reference {vr} is not a {kind} variable")
                except Exception:
                    out.append(bad)
                    self._call_error(f"get{kind}({self._name_of(vr)}) failed:\n" + traceback.format_exc())
            return out

    def _name_of(self, vr):
        return self._specs[vr].name if 0 <= vr < len(self._specs) else f"vr={vr}"

    def _call_error(self, msg):
        self._pending.append(msg.splitlines()[0])
        self._error(msg)

    def get_real(self, vrs):
        # fast path: Reals kept in self.values (no user getter) that hold floats: one comprehension,
        # no getter call per variable (the plant reads 25 outputs per step); anything else (a user
        # getter, a bad value reference, a non-float value) takes the checked path
        try:
            self._pull()
            if self._deferred is not None and not self._eager_vrs.issuperset(vrs):
                self._flush()
            vals = self.values
            names = self._real_names
            out = [vals[names[vr]] for vr in vrs]
            for x in out:
                if type(x) is not float:
                    break
            else:
                return out
        except Exception:
            pass
        return self._get_values("Real", vrs, float, math.nan)

    def get_integer(self, vrs):
        return self._get_values("Integer", vrs, int, 0)

    def get_boolean(self, vrs):
        return self._get_values("Boolean", vrs, bool, False)

    def get_string(self, vrs):
        return self._get_values("String", vrs, str, "")

    def _may_set(self, spec: _Spec) -> Optional[str]:
        mode = self._mode
        if spec.causality == Fmi2Causality.input:
            return None
        if spec.causality == Fmi2Causality.parameter:
            if spec.variability == Fmi2Variability.tunable or mode in ("instantiated", "init"):
                return None
            return f"{spec.name} is a fixed parameter and cannot be changed after initialization"
        if mode in ("instantiated", "init"):
            return None
        return f"{spec.name} ({spec.causality.name}) can only be set before initialization ends"

    def _settable(self, kind: str, vr, x) -> Optional[_Spec]:
        """The declaration of a `kind` variable that may be set now, or None after reporting why the
        value `x` is ignored."""
        spec = self._set[kind].get(vr)
        if spec is None:
            self._call_error(f"set{kind}: {self._name_of(vr)} is not a settable {kind} variable; "
                             f"value {x!r} ignored")
            return None
        why = self._may_set(spec)
        if why is not None:
            self._call_error(f"set{kind} rejected: {why}; value {x!r} ignored")
            return None
        return spec

    def set_real(self, vrs, values):
        try:
            self._pull()   # earlier values the loader wrote must not overwrite these
            # fast path: plain Real inputs (no user setter) in step mode, finite and within bounds
            fast = self._fast_real
            vals = self.values
            for vr, x in zip(vrs, values):
                f = fast.get(vr)
                if f is None or type(x) is not float or not (f[1] <= x <= f[2]):
                    break  # NaN fails the comparison too
                vals[f[0]] = x
            else:
                if self._bad_inputs:
                    for vr in vrs:
                        self._bad_inputs.pop(self._specs[vr].name, None)
                    self._sync_link()
                return
            self._set_real_checked(vrs, values)
            self._sync_link()
        except Exception:
            self._call_error("set_real failed:\n" + traceback.format_exc())

    def _set_real_checked(self, vrs, values):
        try:
            bad = self._bad_inputs
            for vr, x in zip(vrs, values):
                spec = self._settable("Real", vr, x)
                if spec is None:
                    continue
                x = float(x)
                if x - x != 0.0 or (spec.min is not None and x < spec.min) or \
                        (spec.max is not None and x > spec.max):
                    kind = "not finite" if x - x != 0.0 else f"outside [{spec.min}, {spec.max}]"
                    bad[spec.name] = (f"set to {x!r} ({kind}); kept {self.values.get(spec.name)!r}")
                    self._error(f"setReal rejected: {spec.name} = {x!r} is {kind}; the value is not "
                                f"used, and doStep is refused until a valid value is set")
                    continue
                spec.setter(x)
                if bad:
                    bad.pop(spec.name, None)
        except Exception:
            self._call_error("set_real failed:\n" + traceback.format_exc())

    def _set_plain(self, kind, conv, vrs, values):
        try:
            for vr, x in zip(vrs, values):
                spec = self._settable(kind, vr, x)
                if spec is None:
                    continue
                x = conv(x)
                if (spec.min is not None and x < spec.min) or (spec.max is not None and x > spec.max):
                    self._bad_inputs[spec.name] = f"set to {x!r} (outside [{spec.min}, {spec.max}])"
                    self._error(f"set{kind} rejected: {spec.name} = {x!r} is outside "
                                f"[{spec.min}, {spec.max}]")
                    continue
                spec.setter(x)
                self._bad_inputs.pop(spec.name, None)
            self._sync_link()
        except Exception:
            self._call_error(f"set_{kind.lower()} failed:\n" + traceback.format_exc())

    def set_integer(self, vrs, values):
        self._set_plain("Integer", int, vrs, values)

    def set_boolean(self, vrs, values):
        self._set_plain("Boolean", bool, vrs, values)

    def set_string(self, vrs, values):
        self._set_plain("String", str, vrs, values)
