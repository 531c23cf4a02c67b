"""`ReeveSlave`: the pythonfmu base class every reeve_fmu FMU entry subclasses.

It adds to `pythonfmu.Fmi2Slave` (0.7.0) what the FMI standard, `fmpy validate` and robust masters need
and pythonfmu does not do (docs/cosim.md, 'pythonfmu and fmpy', items 1-3):

* declarative variables: `add_real/add_integer/add_boolean/add_string` with causality, variability,
  initial, unit (SI, with `UnitDefinitions` + `BaseUnit` exponents and display units such as rpm/mm),
  optional `declaredType` (TypeDefinitions), `derivative` relations, min/max, and explicit
  `ModelStructure` output dependencies (`dependencies=()` -> `dependencies=""`: the output is a pure
  function of the state, no algebraic loop). `InitialUnknowns` are generated consistently.
  Integer/Boolean default to `variability="discrete"`. The XML passes `fmpy validate` with no problems.
* values live in the plain dict `self.values` (name -> builtin scalar); subclass code reads inputs
  and writes outputs there (or passes `getter=` for computed outputs).
* honest FMU state: `get_hidden_state()/set_hidden_state()` hooks; the base snapshots *all* of it
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
from xml.etree.ElementTree import Element, SubElement

from pythonfmu import Fmi2Slave
from pythonfmu.default_experiment import DefaultExperiment
from pythonfmu.enums import Fmi2Causality, Fmi2Initial, Fmi2Status, Fmi2Variability
from pythonfmu.variables import Boolean, Integer, Real, String

from . import fastlink
from ._bootstrap import STAMP_NAME, package_hash

__all__ = [
    "ReeveSlave", "DefaultExperiment", "Fmi2Status", "UNITS", "TYPES", "STATE_FORMAT",
    "canonical_state",
]

STATE_FORMAT = "reeve_fmu.state/1"

# --------------------------------------------------------------------------------------------------
# Units: name -> (BaseUnit exponents, factor, {display unit: (factor, offset)})
# value_in_display_unit = factor * value_in_unit + offset (FMI 2.0 DisplayUnit semantics)
# --------------------------------------------------------------------------------------------------
_RPM = 60.0 / (2.0 * math.pi)
_DEG = 180.0 / math.pi
UNITS: dict[str, tuple[dict[str, int], float, dict[str, tuple[float, float]]]] = {
    "1": ({}, 1.0, {"%": (100.0, 0.0)}),
    "m": ({"m": 1}, 1.0, {"mm": (1000.0, 0.0), "km": (1e-3, 0.0)}),
    "m2": ({"m": 2}, 1.0, {"mm2": (1e6, 0.0)}),
    "m/s": ({"m": 1, "s": -1}, 1.0, {"mm/s": (1000.0, 0.0)}),
    "m/s2": ({"m": 1, "s": -2}, 1.0, {}),
    "m/s3": ({"m": 1, "s": -3}, 1.0, {}),
    "s": ({"s": 1}, 1.0, {"ms": (1000.0, 0.0)}),
    "Hz": ({"s": -1}, 1.0, {}),
    "1/s": ({"s": -1}, 1.0, {}),
    "kg": ({"kg": 1}, 1.0, {"t": (1e-3, 0.0)}),
    "kg/m": ({"kg": 1, "m": -1}, 1.0, {}),
    "kg.m2": ({"kg": 1, "m": 2}, 1.0, {}),
    "N": ({"kg": 1, "m": 1, "s": -2}, 1.0, {"kN": (1e-3, 0.0)}),
    "N/m": ({"kg": 1, "s": -2}, 1.0, {"kN/mm": (1e-6, 0.0)}),
    "N.s/m": ({"kg": 1, "s": -1}, 1.0, {}),
    "N.m": ({"kg": 1, "m": 2, "s": -2}, 1.0, {"kN.m": (1e-3, 0.0)}),
    "N.m2": ({"kg": 1, "m": 3, "s": -2}, 1.0, {}),
    "N.m/rad": ({"kg": 1, "m": 2, "s": -2, "rad": -1}, 1.0, {}),
    "N.m.s/rad": ({"kg": 1, "m": 2, "s": -1, "rad": -1}, 1.0, {}),
    "Pa": ({"kg": 1, "m": -1, "s": -2}, 1.0, {"MPa": (1e-6, 0.0), "N/mm2": (1e-6, 0.0)}),
    "J": ({"kg": 1, "m": 2, "s": -2}, 1.0, {"kJ": (1e-3, 0.0)}),
    "W": ({"kg": 1, "m": 2, "s": -3}, 1.0, {"kW": (1e-3, 0.0)}),
    "rad": ({"rad": 1}, 1.0, {"deg": (_DEG, 0.0)}),
    "rad/s": ({"rad": 1, "s": -1}, 1.0, {"rpm": (_RPM, 0.0), "deg/s": (_DEG, 0.0)}),
    "rad/s2": ({"rad": 1, "s": -2}, 1.0, {"deg/s2": (_DEG, 0.0)}),
    "rad/s3": ({"rad": 1, "s": -3}, 1.0, {}),
    "A": ({"A": 1}, 1.0, {}),
    "V": ({"kg": 1, "m": 2, "s": -3, "A": -1}, 1.0, {}),
    "Ohm": ({"kg": 1, "m": 2, "s": -3, "A": -2}, 1.0, {"mOhm": (1e3, 0.0)}),
    "H": ({"kg": 1, "m": 2, "s": -2, "A": -2}, 1.0, {"mH": (1e3, 0.0)}),
    "Wb": ({"kg": 1, "m": 2, "s": -2, "A": -1}, 1.0, {"mWb": (1e3, 0.0)}),
    "N.m/A": ({"kg": 1, "m": 2, "s": -2, "A": -1}, 1.0, {}),
    "K": ({"K": 1}, 1.0, {"degC": (1.0, -273.15)}),
}

# TypeDefinitions: name -> (quantity, unit, default display unit or None)
TYPES: dict[str, tuple[str, str, Optional[str]]] = {
    "Position": ("Length", "m", None),
    "Length": ("Length", "m", None),
    "Velocity": ("Velocity", "m/s", None),
    "Acceleration": ("Acceleration", "m/s2", None),
    "Jerk": ("Jerk", "m/s3", None),
    "Force": ("Force", "N", None),
    "Torque": ("Torque", "N.m", None),
    "Angle": ("Angle", "rad", None),
    "AngularVelocity": ("AngularVelocity", "rad/s", "rpm"),
    "AngularAcceleration": ("AngularAcceleration", "rad/s2", None),
    "Mass": ("Mass", "kg", None),
    "Time": ("Time", "s", None),
    "Stiffness": ("TranslationalSpringConstant", "N/m", None),
    "Damping": ("TranslationalDampingConstant", "N.s/m", None),
    "Inertia": ("MomentOfInertia", "kg.m2", None),
    "Power": ("Power", "W", None),
    "Voltage": ("ElectricPotential", "V", None),
    "Current": ("ElectricCurrent", "A", None),
}

_CAUS = {c.name: c for c in Fmi2Causality}
_VAR = {v.name: v for v in Fmi2Variability}
_INIT = {i.name: i for i in Fmi2Initial}
_KINDS = ("Real", "Integer", "Boolean", "String")
_PYVAR = {"Real": Real, "Integer": Integer, "Boolean": Boolean, "String": String}


def _enum(table, value, what):
    if value is None:
        return None
    if isinstance(value, str):
        try:
            return table[value]
        except KeyError:
            raise ValueError(f"unknown {what} {value!r}; expected one of {sorted(table)}") from None
    return table[value.name]


def _fmt(x) -> str:
    """XML number/bool text: shortest round-trip repr for floats (pythonfmu's '.16g' is not exact)."""
    if isinstance(x, bool):
        return "true" if x else "false"
    if isinstance(x, float):
        if x != x or x in (math.inf, -math.inf):
            raise ValueError(f"non-finite value {x!r} cannot be written to modelDescription.xml")
        return repr(x)
    return str(x)


def canonical_state(obj, path="state"):
    """Deep copy of `obj` restricted to JSON-exact builtin types.

    dict (str keys) / list / tuple (-> list) / float / int / bool / str / None. Objects with
    `tolist()` (numpy arrays and scalars) are converted. Anything else raises TypeError naming the
    path, so a bad hidden state is found at getFMUstate time, not silently lost at serialisation.
    """
    t = type(obj)
    if t is float or t is int or t is bool or t is str or obj is None:
        return obj
    if t is list and all(type(v) is float for v in obj):
        return obj[:]  # fast path: ndarray.tolist() of floats
    if isinstance(obj, dict):
        out = {}
        for k, v in obj.items():
            if type(k) is not str:
                raise TypeError(f"{path}: dict key {k!r} is {type(k).__name__}, must be str "
                                f"(JSON would turn it into a string)")
            out[k] = canonical_state(v, f"{path}.{k}")
        return out
    if t is list or t is tuple:
        return [canonical_state(v, f"{path}[{i}]") for i, v in enumerate(obj)]
    if isinstance(obj, bool):
        return bool(obj)
    if isinstance(obj, int):
        return int(obj)
    if isinstance(obj, float):
        return float(obj)
    if isinstance(obj, str):
        return str(obj)
    if hasattr(obj, "tolist"):  # numpy array / scalar, without importing numpy
        return canonical_state(obj.tolist(), path)
    raise TypeError(f"{path}: {t.__name__} is not allowed in FMU state (use builtin types; "
                    f"ndarray -> .tolist())")


class _Spec:
    __slots__ = ("name", "kind", "vr", "causality", "variability", "initial", "unit", "display_unit",
                 "declared_type", "description", "start", "min", "max", "nominal", "derivative_of",
                 "dependencies", "getter", "setter", "index")

    def __init__(self, **kw):
        for k in self.__slots__:
            setattr(self, k, kw.get(k))


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


class ReeveSlave(Fmi2Slave):
    """Base class of reeve_fmu co-simulation slaves. See the module docstring for the contract."""

    #: class attribute or set in define() with set_default_experiment()
    default_experiment: Optional[DefaultExperiment] = None
    #: relative tolerance (of dt) for the check currentCommunicationPoint == end of the last step
    time_tolerance: float = 1e-6

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

    # ------------------------------------------------------------------ declaration helpers
    def set_default_experiment(self, start_time=0.0, stop_time=None, step_size=None, tolerance=None):
        self.default_experiment = DefaultExperiment(start_time=start_time, stop_time=stop_time,
                                                    step_size=step_size, tolerance=tolerance)

    def add_real(self, name: str, causality="local", variability=None, unit: Optional[str] = None,
                 description: Optional[str] = None, start: Optional[float] = None, *, initial=None,
                 declared_type: Optional[str] = None, derivative_of: Optional[str] = None,
                 display_unit: Optional[str] = None, min: Optional[float] = None,
                 max: Optional[float] = None, nominal: Optional[float] = None,
                 dependencies: Optional[Iterable[str]] = (), getter: Optional[Callable] = None,
                 setter: Optional[Callable] = None) -> str:
        """Declare a Real variable; returns its name. Value in self.values[name] unless getter given.

        dependencies (outputs only): names of the *inputs* the output depends on directly within a
        step (default () -> `dependencies=""`). Pass None to omit the attribute (= depends on all).
        """
        if declared_type is not None:
            if declared_type not in TYPES:
                raise ValueError(f"{name}: unknown declared_type {declared_type!r}; known: {sorted(TYPES)}")
            tunit = TYPES[declared_type][1]
            if unit is None:
                unit = tunit
            elif unit != tunit:
                raise ValueError(f"{name}: unit {unit!r} differs from {declared_type}'s unit {tunit!r}")
        if unit is not None and unit not in UNITS:
            raise ValueError(f"{name}: unknown unit {unit!r}; known: {sorted(UNITS)}")
        if display_unit is not None and (unit is None or display_unit not in UNITS[unit][2]):
            raise ValueError(f"{name}: display unit {display_unit!r} is not defined for unit {unit!r}")
        if start is not None:
            start = float(start)
        return self._add("Real", name, causality, variability, description, start, initial,
                         unit=unit, display_unit=display_unit, declared_type=declared_type,
                         derivative_of=derivative_of, min=min, max=max, nominal=nominal,
                         dependencies=dependencies, getter=getter, setter=setter)

    def add_integer(self, name, causality="local", variability=None, description=None, start=None, *,
                    initial=None, min=None, max=None, dependencies=(), getter=None, setter=None) -> str:
        return self._add("Integer", name, causality, variability, description,
                         None if start is None else int(start), initial, min=min, max=max,
                         dependencies=dependencies, getter=getter, setter=setter)

    def add_boolean(self, name, causality="local", variability=None, description=None, start=None, *,
                    initial=None, dependencies=(), getter=None, setter=None) -> str:
        return self._add("Boolean", name, causality, variability, description,
                         None if start is None else bool(start), initial,
                         dependencies=dependencies, getter=getter, setter=setter)

    def add_string(self, name, causality="parameter", variability=None, description=None, start=None,
                   *, initial=None, getter=None, setter=None) -> str:
        return self._add("String", name, causality, variability, description,
                         None if start is None else str(start), initial, dependencies=(),
                         getter=getter, setter=setter)

    def _add(self, kind, name, causality, variability, description, start, initial, **kw) -> str:
        if name in self._by_name:
            raise ValueError(f"variable {name!r} declared twice")
        caus = _enum(_CAUS, causality, "causality") or Fmi2Causality.local
        var = _enum(_VAR, variability, "variability")
        ini = _enum(_INIT, initial, "initial")
        if var is None:
            if caus in (Fmi2Causality.parameter, Fmi2Causality.calculatedParameter):
                var = Fmi2Variability.fixed
            elif kind == "Real":
                var = Fmi2Variability.continuous
            else:
                var = Fmi2Variability.discrete
        if kind != "Real" and var == Fmi2Variability.continuous:
            raise ValueError(f"{name}: {kind} variables cannot be continuous (use discrete)")
        if ini is None:
            if caus == Fmi2Causality.parameter or var == Fmi2Variability.constant:
                ini = Fmi2Initial.exact
            elif caus == Fmi2Causality.input:
                ini = None
            else:
                ini = Fmi2Initial.calculated
        if caus == Fmi2Causality.input and ini is not None:
            raise ValueError(f"{name}: inputs take no 'initial' attribute")
        if start is None and (caus in (Fmi2Causality.input, Fmi2Causality.parameter)
                              or ini in (Fmi2Initial.exact, Fmi2Initial.approx)):
            raise ValueError(f"{name}: a start value is required ({caus.name}, initial={ini and ini.name})")
        if isinstance(start, float) and not math.isfinite(start):
            raise ValueError(f"{name}: start value must be finite, got {start!r}")
        if kw.get("dependencies") is not None and caus != Fmi2Causality.output:
            kw["dependencies"] = None
        if kw.get("derivative_of") is not None:
            st = self._by_name.get(kw["derivative_of"])
            if st is None or st.kind != "Real":
                raise ValueError(f"{name}: derivative_of {kw['derivative_of']!r} must name a Real "
                                 f"variable declared before it")
        vr = len(self._specs)
        spec = _Spec(name=name, kind=kind, vr=vr, causality=caus, variability=var, initial=ini,
                     description=description, start=start, index=vr + 1, **kw)
        default = {"Real": 0.0, "Integer": 0, "Boolean": False, "String": ""}[kind]
        self.values[name] = default if start is None else start
        self._specs.append(spec)
        self._by_name[name] = spec

        values = self.values
        getter = kw.get("getter") or (lambda _n=name, _v=values: _v[_n])
        settable = (caus in (Fmi2Causality.input, Fmi2Causality.parameter)
                    or (ini in (Fmi2Initial.exact, Fmi2Initial.approx)
                        and var != Fmi2Variability.constant))
        if kw.get("setter") is not None and not settable:
            raise ValueError(f"{name}: setter= only makes sense for inputs, parameters and "
                             f"variables with initial exact/approx")
        if settable:
            user_setter = kw.get("setter")
            if user_setter is not None:
                self._user_setters[name] = user_setter

            def setter(v, _n=name, _v=values, _s=user_setter):
                _v[_n] = v
                if _s is not None:
                    _s(v)
        else:
            setter = None
        pyvar = _PYVAR[kind](name, causality=caus, variability=var, initial=ini,
                             description=description, getter=getter, setter=setter, start=start)
        self.register_variable(pyvar)
        assert pyvar.value_reference == vr, "value references out of step with pythonfmu"
        self._get[kind][vr] = getter
        self._real_names.append(name if kind == "Real" and kw.get("getter") is None else None)
        if settable:
            spec.setter = setter
            self._set[kind][vr] = spec
        return name

    def vr(self, name: str) -> int:
        return self._by_name[name].vr

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
            self.time = t + dt
            return True
        except Exception:  # pragma: no cover - belt and braces
            self._error("do_step failed:\n" + traceback.format_exc())
            return False

    def _reject_step(self, t, dt, now) -> bool:
        if not (dt > 0.0) or dt == math.inf:
            self._error(f"doStep rejected: communicationStepSize={dt!r} at t={t!r} (must be finite and > 0)")
        elif t - t != 0.0:
            self._error(f"doStep rejected: currentCommunicationPoint={t!r} is not finite")
        else:
            self._error(f"doStep rejected: currentCommunicationPoint={t!r} but the FMU is at "
                        f"t={now!r} (steps must be contiguous; use setFMUstate to go back)")
        return False

    def _refuse_step(self, t, dt) -> bool:
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
        # no getter call per variable (the plant's 25 outputs: ~3x faster); anything else (a user
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
            table = self._set["Real"]
            bad = self._bad_inputs
            for vr, x in zip(vrs, values):
                spec = table.get(vr)
                if spec is None:
                    self._call_error(f"setReal: {self._name_of(vr)} is not a settable Real variable; "
                                     f"value {x!r} ignored")
                    continue
                if spec.causality != Fmi2Causality.input or self._mode != "step":
                    why = self._may_set(spec)
                    if why is not None:
                        self._call_error(f"setReal rejected: {why}; value {x!r} ignored")
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
            table = self._set[kind]
            for vr, x in zip(vrs, values):
                spec = table.get(vr)
                if spec is None:
                    self._call_error(f"set{kind}: {self._name_of(vr)} is not a settable {kind} "
                                     f"variable; value {x!r} ignored")
                    continue
                why = self._may_set(spec)
                if why is not None:
                    self._call_error(f"set{kind} rejected: {why}; value {x!r} ignored")
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

    # ------------------------------------------------------------------ FMU state
    def _get_fmu_state(self):
        try:
            self._pull()
            self._flush()
            hidden = self.get_hidden_state() if self._initialized else {}
            return canonical_state({
                "format": STATE_FORMAT,
                "model": type(self).__name__,
                "values": self.values,
                "time": self.time,
                "start_time": self.start_time,
                "stop_time": self.stop_time,
                "mode": self._mode,
                "initialized": self._initialized,
                "bad_inputs": self._bad_inputs,
                "hidden": hidden,
            })
        except Exception:
            msg = "getFMUstate failed:\n" + traceback.format_exc()
            self._call_error(msg)
            return {"format": STATE_FORMAT, "error": msg}

    def _set_fmu_state(self, state):
        try:
            if not isinstance(state, dict) or state.get("format") != STATE_FORMAT:
                raise ValueError(f"not a {STATE_FORMAT} state: {str(state)[:200]!r}")
            if "error" in state:
                raise ValueError("this state was captured from a failing getFMUstate:\n" + state["error"])
            if state.get("model") != type(self).__name__:
                raise ValueError(f"state belongs to model {state.get('model')!r}, not "
                                 f"{type(self).__name__!r}")
            values = state["values"]
            unknown = set(values) - set(self._by_name)
            if unknown:
                raise ValueError(f"state has unknown variables {sorted(unknown)[:10]}")
            fixed_changed = any(
                s.causality == Fmi2Causality.parameter and s.variability == Fmi2Variability.fixed
                and values.get(s.name, self.values[s.name]) != self.values[s.name]
                for s in self._specs)
            if self._fault is not None and state["initialized"]:
                raise RuntimeError("cannot restore into a faulty instance (reset it first):\n"
                                   + self._fault)
            self._pull()
            self._deferred = None
            self.values.update(values)
            self.time = state["time"]
            self.start_time = state["start_time"]
            self.stop_time = state["stop_time"]
            self._set_mode(state["mode"])
            self._bad_inputs = dict(state["bad_inputs"])
            self._pending.clear()
            self._dirty = None
            if state["initialized"] and (not self._initialized or fixed_changed):
                # (re)build the model from the restored parameters, then put the restored values
                # back (initialize() typically writes initial outputs)
                try:
                    self.initialize()
                except Exception:
                    self._fault = "initialize() during setFMUstate failed:\n" + traceback.format_exc()
                    raise
                self.values.update(values)
            self._initialized = bool(state["initialized"])
            for name, v in values.items():
                user_setter = self._user_setters.get(name)
                if user_setter is not None:
                    user_setter(v)
            if self._initialized:
                self.set_hidden_state(canonical_state(state["hidden"]))
            self._sync_link()
        except Exception:
            self._call_error("setFMUstate failed:\n" + traceback.format_exc())
            self._sync_link()

    @staticmethod
    def _fmu_state_to_bytes(state) -> bytes:
        try:
            return json.dumps(state, allow_nan=True, separators=(",", ":")).encode("utf-8")
        except Exception:
            return json.dumps({"format": STATE_FORMAT,
                               "error": "serializeFMUstate failed:\n" + traceback.format_exc()}
                              ).encode("utf-8")

    @staticmethod
    def _fmu_state_from_bytes(data: bytes):
        try:
            return json.loads(bytes(data).decode("utf-8"))
        except Exception:
            return {"format": STATE_FORMAT,
                    "error": "deSerializeFMUstate failed:\n" + traceback.format_exc()}

    # ------------------------------------------------------------------ modelDescription.xml
    def to_xml(self, model_options: dict = dict()) -> Element:
        """pythonfmu's XML plus units, types, derivatives and a complete ModelStructure.

        Only called at build time: raises if define() failed, so a broken entry never builds."""
        if self._fault is not None:
            raise RuntimeError(self._fault)
        root = super().to_xml(model_options)
        if self.description:
            root.set("description", self.description)
        for tag in ("ModelVariables", "ModelStructure", "DefaultExperiment"):
            for node in root.findall(tag):
                root.remove(node)
        children = list(root)
        cosim_pos = next(i for i, c in enumerate(children) if c.tag == "CoSimulation")

        used_types = sorted({s.declared_type for s in self._specs if s.declared_type})
        used_units = {s.unit for s in self._specs if s.unit}
        used_units |= {TYPES[t][1] for t in used_types}
        insert_at = cosim_pos + 1
        if used_units:
            ud = Element("UnitDefinitions")
            for u in sorted(used_units):
                exps, factor, displays = UNITS[u]
                un = SubElement(ud, "Unit", {"name": u})
                battr = {k: str(v) for k, v in exps.items()}
                if factor != 1.0:
                    battr["factor"] = _fmt(factor)
                SubElement(un, "BaseUnit", battr)
                for dname, (f, off) in displays.items():
                    dattr = {"name": dname, "factor": _fmt(f)}
                    if off:
                        dattr["offset"] = _fmt(off)
                    SubElement(un, "DisplayUnit", dattr)
            root.insert(insert_at, ud)
            insert_at += 1
        if used_types:
            td = Element("TypeDefinitions")
            for t in used_types:
                quantity, unit, disp = TYPES[t]
                st = SubElement(td, "SimpleType", {"name": t})
                rattr = {"quantity": quantity, "unit": unit}
                if disp:
                    rattr["displayUnit"] = disp
                SubElement(st, "Real", rattr)
            root.insert(insert_at, td)
            insert_at += 1
        # LogCategories stays where pythonfmu put it (right after CoSimulation, now after types)
        children = list(root)
        log_pos = next((i for i, c in enumerate(children) if c.tag == "LogCategories"), None)
        de_pos = (log_pos + 1) if log_pos is not None else insert_at
        de = getattr(self, "default_experiment", None)
        if de is not None:
            attr = {}
            for key, val in (("startTime", de.start_time), ("stopTime", de.stop_time),
                             ("tolerance", de.tolerance), ("stepSize", de.step_size)):
                if val is not None:
                    attr[key] = _fmt(float(val))
            root.insert(de_pos, Element("DefaultExperiment", attr))

        mv = SubElement(root, "ModelVariables")
        for s in self._specs:
            attr = {"name": s.name, "valueReference": str(s.vr)}
            if s.description:
                attr["description"] = s.description
            attr["causality"] = s.causality.name
            attr["variability"] = s.variability.name
            if s.initial is not None:
                attr["initial"] = s.initial.name
            sv = SubElement(mv, "ScalarVariable", attr)
            tattr = {}
            if s.declared_type:
                tattr["declaredType"] = s.declared_type
            if s.kind == "Real":
                if s.unit:
                    tattr["unit"] = s.unit
                if s.display_unit:
                    tattr["displayUnit"] = s.display_unit
            for key in ("min", "max", "nominal"):
                v = getattr(s, key)
                if v is not None:
                    tattr[key] = _fmt(float(v) if s.kind == "Real" else v)
            write_start = (s.causality in (Fmi2Causality.input, Fmi2Causality.parameter)
                           or s.initial in (Fmi2Initial.exact, Fmi2Initial.approx))
            if write_start:
                tattr["start"] = _fmt(s.start)
            if s.derivative_of:
                tattr["derivative"] = str(self._by_name[s.derivative_of].index)
            SubElement(sv, s.kind, tattr)

        ms = SubElement(root, "ModelStructure")
        outputs = [s for s in self._specs if s.causality == Fmi2Causality.output]
        if outputs:
            on = SubElement(ms, "Outputs")
            for s in outputs:
                SubElement(on, "Unknown", self._unknown_attr(s))
        derivs = [s for s in self._specs if s.derivative_of]
        if derivs:
            dn = SubElement(ms, "Derivatives")
            for s in derivs:  # no dependencies attribute: depends on states (and maybe inputs)
                SubElement(dn, "Unknown", {"index": str(s.index)})
        initial = set()
        for s in self._specs:
            if s.causality == Fmi2Causality.output and s.initial in (Fmi2Initial.approx, Fmi2Initial.calculated):
                initial.add(s.index)
            if s.causality == Fmi2Causality.calculatedParameter:
                initial.add(s.index)
        for s in derivs:
            for v in (self._by_name[s.derivative_of], s):
                if v.initial in (Fmi2Initial.approx, Fmi2Initial.calculated):
                    initial.add(v.index)
        if initial:
            iu = SubElement(ms, "InitialUnknowns")
            for idx in sorted(initial):
                SubElement(iu, "Unknown", {"index": str(idx)})
        return root

    def _unknown_attr(self, s: _Spec) -> dict:
        attr = {"index": str(s.index)}
        if s.dependencies is not None:
            idx = []
            for d in s.dependencies:
                dep = self._by_name.get(d)
                if dep is None or dep.causality != Fmi2Causality.input:
                    raise ValueError(f"{s.name}: dependency {d!r} is not an input variable")
                idx.append(dep.index)
            attr["dependencies"] = " ".join(str(i) for i in sorted(set(idx)))
        return attr
