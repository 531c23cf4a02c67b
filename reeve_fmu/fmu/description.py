"""modelDescription.xml of a `ReeveSlave`: the variable declarations (causality, variability, initial,
SI unit with `UnitDefinitions`/`BaseUnit` exponents and display units, declaredType, derivative, min/max,
`ModelStructure` dependencies) and the XML writer that adds to pythonfmu's what `fmpy validate` asks for.

A new unit goes into UNITS, a new declared type into TYPES; `Declarations` is mixed into `ReeveSlave`
(reeve_fmu.fmu.slave) and only writes the declarations and the XML: values and calls live there.
"""
from __future__ import annotations

import math
from typing import Callable, Iterable, Optional
from xml.etree.ElementTree import Element, SubElement

from pythonfmu.default_experiment import DefaultExperiment
from pythonfmu.enums import Fmi2Causality, Fmi2Initial, Fmi2Variability
from pythonfmu.variables import Boolean, Integer, Real, String

__all__ = ["Declarations", "UNITS", "TYPES"]

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
_FMI3_KIND = {"Real": "Float64", "Integer": "Int32", "Boolean": "Boolean", "String": "String"}
#: FMI 2.0 CoSimulation attributes that FMI 3.0 does not have
FMI2_ONLY_CAPABILITIES = ("canInterpolateInputs", "canNotUseMemoryManagementFunctions",
                          "canRunAsynchronuously", "maxOutputDerivativeOrder")
#: what the FMI 3.0 adapter declares beyond the FMI 2.0 flags
FMI3_CAPABILITIES = {"hasEventMode": "true", "mightReturnEarlyFromDoStep": "false",
                     "canReturnEarlyAfterIntermediateUpdate": "false", "providesIntermediateUpdate": "false"}
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


def _var_attr(name: str, vr: int, description: Optional[str], spec: "_Spec") -> dict:
    """A variable's attributes in both versions, in this order: name, value reference, description,
    causality, variability, initial (of `spec`)."""
    attr = {"name": name, "valueReference": str(vr)}
    if description:
        attr["description"] = description
    attr["causality"] = spec.causality.name
    attr["variability"] = spec.variability.name
    if spec.initial is not None:
        attr["initial"] = spec.initial.name
    return attr


def _type_attr(quantity, unit, display_unit) -> dict:
    attr = {"quantity": quantity, "unit": unit}
    if display_unit:
        attr["displayUnit"] = display_unit
    return attr


class _Spec:
    __slots__ = ("name", "kind", "vr", "causality", "variability", "initial", "unit", "display_unit",
                 "declared_type", "description", "start", "min", "max", "nominal", "derivative_of",
                 "dependencies", "getter", "setter", "index")

    def __init__(self, **kw):
        for k in self.__slots__:
            setattr(self, k, kw.get(k))



class Declarations:
    """Declaring variables (add_real/add_integer/add_boolean/add_string) and writing
    modelDescription.xml; mixed into ReeveSlave, whose constructor creates the tables used here."""

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

    def add_array(self, name: str, elements: Iterable[str], description: Optional[str] = None) -> str:
        """An FMI 3.0 array variable whose elements are the declared scalars `elements` (in that order;
        they must agree in type, causality, variability, initial, unit). The FMI 2.0 FMU does not show
        it; in the FMI 3.0 FMU the scalars stay and the array is one more variable over the same values."""
        elements = list(elements)
        if name in self._by_name or any(a[0] == name for a in self._arrays):
            raise ValueError(f"variable {name!r} declared twice")
        specs = [self._by_name.get(e) for e in elements]
        if not specs or None in specs or specs[0].kind == "String":
            raise ValueError(f"{name}: the elements {elements} must be declared numeric or Boolean variables")
        keys = {(s.kind, s.causality, s.variability, s.initial, s.unit, s.declared_type, s.display_unit)
                for s in specs}
        if len(keys) != 1:
            raise ValueError(f"{name}: the elements {elements} differ in causality, variability, initial, "
                             f"unit or type")
        self._arrays.append((name, specs, description))
        return name

    def add_output_arrays(self) -> list:
        """FMI 3.0 arrays over the declared outputs: `<p>.x`, `<p>.y`, `<p>.z` as the vector `<p>` (e.g.
        payload.rotation), and over the sheaves (the outputs `<s>.tension_in`, in declaration order)
        sheaves.angle, .speed, .tension_in, .tension_out. Returns the arrays' names."""
        outs = [s.name for s in self._specs if s.causality == Fmi2Causality.output]
        have, names = set(outs), []
        for n in outs:
            base = n[:-2]
            if n.endswith(".x") and {base + ".y", base + ".z"} <= have and base not in self._by_name:
                names.append(self.add_array(base, [base + ".x", base + ".y", base + ".z"],
                                            description=f"{base} as the vector (x, y, z)"))
        sheaves = [n[:-len(".tension_in")] for n in outs if n.endswith(".tension_in")]
        for q in ("angle", "speed", "tension_in", "tension_out"):
            if sheaves and all(f"{s}.{q}" in have for s in sheaves):
                names.append(self.add_array(f"sheaves.{q}", [f"{s}.{q}" for s in sheaves],
                                            description=f"{q} of the sheaves {', '.join(sheaves)}"))
        return names

    def fmi3_arrays(self) -> str:
        """The FMI 3.0 adapter's table of array variables (resources/reeve_fmi3_arrays.txt): one line per
        array, its FMI 3.0 value reference, its size, the FMI 2.0 value references of its elements."""
        n = len(self._specs) + 1
        return "".join(f"{n + i} {len(specs)} {' '.join(str(s.vr) for s in specs)}\n"
                       for i, (_, specs, _) in enumerate(self._arrays))

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

        used_types, unit_defs = self._unit_definitions()
        insert_at = cosim_pos + 1
        if unit_defs is not None:
            root.insert(insert_at, unit_defs)
            insert_at += 1
        if used_types:
            td = Element("TypeDefinitions")
            for t in used_types:
                quantity, unit, disp = TYPES[t]
                st = SubElement(td, "SimpleType", {"name": t})
                SubElement(st, "Real", _type_attr(quantity, unit, disp))
            root.insert(insert_at, td)
            insert_at += 1
        # LogCategories stays where pythonfmu put it (right after CoSimulation, now after types)
        children = list(root)
        log_pos = next((i for i, c in enumerate(children) if c.tag == "LogCategories"), None)
        de_pos = (log_pos + 1) if log_pos is not None else insert_at
        de = self._default_experiment_xml()
        if de is not None:
            root.insert(de_pos, de)

        mv = SubElement(root, "ModelVariables")
        for s in self._specs:
            sv = SubElement(mv, "ScalarVariable", _var_attr(s.name, s.vr, s.description, s))
            tattr = self._value_attr(s, self._by_name[s.derivative_of].index if s.derivative_of else None)
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
        initial = {v.index for v in self._initial_unknowns()}
        if initial:
            iu = SubElement(ms, "InitialUnknowns")
            for idx in sorted(initial):
                SubElement(iu, "Unknown", {"index": str(idx)})
        return root

    def to_xml3(self, fmi2: Element) -> Element:
        """The FMI 3.0 co-simulation modelDescription of the same declarations (fmi3 adapter of the
        native loader, reeve_fmu/fmu/native/fmi3.c). `fmi2` is the FMU's FMI 2.0 document: its header
        and capability flags carry over (FMUstate spelled FMUState), the rest is written here. As in
        the FMI 3.0 Reference FMUs, value reference 0 is the independent variable `time`; every
        declared variable has its FMI 2.0 value reference + 1."""
        if self._fault is not None:
            raise RuntimeError(self._fault)
        head = {k: v for k, v in fmi2.attrib.items() if k not in ("fmiVersion", "guid", "numberOfEventIndicators")}
        root = Element("fmiModelDescription", {"fmiVersion": "3.0", "modelName": head.pop("modelName"),
                                               "instantiationToken": "{" + fmi2.get("guid") + "}", **head})
        cs2 = fmi2.find("CoSimulation")
        cs = {k.replace("FMUstate", "FMUState"): v for k, v in cs2.attrib.items()
              if k not in FMI2_ONLY_CAPABILITIES}
        cs.update(FMI3_CAPABILITIES)
        if getattr(self, "might_return_early", False):
            cs["mightReturnEarlyFromDoStep"] = "true"
        SubElement(root, "CoSimulation", cs)
        used_types, unit_defs = self._unit_definitions(extra=("s",))
        if unit_defs is not None:
            root.append(unit_defs)
        if used_types:
            td = SubElement(root, "TypeDefinitions")
            for t in used_types:
                quantity, unit, disp = TYPES[t]
                SubElement(td, "Float64Type", {"name": t, **_type_attr(quantity, unit, disp)})
        cats = fmi2.find("LogCategories")
        if cats is not None:
            lc = SubElement(root, "LogCategories")
            for c in cats:
                SubElement(lc, "Category", {k: v.replace("fmi2", "fmi3") for k, v in c.attrib.items()})
        de = self._default_experiment_xml()
        if de is not None:
            root.append(de)
        mv = SubElement(root, "ModelVariables")
        SubElement(mv, "Float64", {"name": "time", "valueReference": "0", "causality": "independent",
                                   "variability": "continuous", "description": "Simulation time",
                                   "unit": "s"})
        for s in self._specs:
            attr = _var_attr(s.name, s.vr + 1, s.description, s)
            attr.update(self._value_attr(s, self._by_name[s.derivative_of].vr + 1 if s.derivative_of else None))
            start = attr.pop("start", None) if s.kind == "String" else None
            node = SubElement(mv, _FMI3_KIND[s.kind], attr)
            if start is not None:
                SubElement(node, "Start", {"value": start})
        array_vr = {}
        for i, (name, specs, description) in enumerate(self._arrays):
            array_vr[name] = vr = len(self._specs) + 1 + i
            first = specs[0]
            attr = _var_attr(name, vr, description, first)
            attr.update(self._value_attr(first, None))
            for key in ("min", "max", "nominal"):
                if len({getattr(s, key) for s in specs}) > 1:
                    attr.pop(key, None)   # differs per element: in the scalars only (an array has one)
            if "start" in attr:
                attr["start"] = " ".join(_fmt(s.start) for s in specs)
            node = SubElement(mv, _FMI3_KIND[first.kind], attr)
            SubElement(node, "Dimension", {"start": str(len(specs))})
        ms = SubElement(root, "ModelStructure")
        for s in self._specs:
            if s.causality == Fmi2Causality.output:
                SubElement(ms, "Output", self._unknown_attr(s, "valueReference", lambda v: v.vr + 1))
        for name, specs, _ in self._arrays:
            if specs[0].causality == Fmi2Causality.output:
                deps = [self._unknown_attr(s, "valueReference", lambda v: v.vr + 1).get("dependencies")
                        for s in specs]
                attr = {"valueReference": str(array_vr[name])}
                if None not in deps:
                    attr["dependencies"] = " ".join(sorted({d for x in deps for d in x.split()}, key=int))
                SubElement(ms, "Output", attr)
        initial = [(s.vr + 1) for s in self._initial_unknowns()]
        initial += [array_vr[name] for name, specs, _ in self._arrays
                    if specs[0].causality == Fmi2Causality.output
                    and specs[0].initial in (Fmi2Initial.approx, Fmi2Initial.calculated)]
        for vr in initial:
            SubElement(ms, "InitialUnknown", {"valueReference": str(vr)})
        return root

    def _unknown_attr(self, s: _Spec, key: str = "index", ref=lambda v: v.index) -> dict:
        """An output's ModelStructure entry: `key` "index" (FMI 2.0) or "valueReference" (3.0), and
        `ref(spec)` the number written for it and for its dependencies."""
        attr = {key: str(ref(s))}
        if s.dependencies is not None:
            idx = []
            for d in s.dependencies:
                dep = self._by_name.get(d)
                if dep is None or dep.causality != Fmi2Causality.input:
                    raise ValueError(f"{s.name}: dependency {d!r} is not an input variable")
                idx.append(ref(dep))
            attr["dependencies"] = " ".join(str(i) for i in sorted(set(idx)))
        return attr

    def _value_attr(self, s: _Spec, derivative_ref) -> dict:
        """The attributes of a variable's value: type, unit, bounds, start, derivative (written as
        `derivative_ref`: the index in FMI 2.0, the value reference in FMI 3.0)."""
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
        if s.causality in (Fmi2Causality.input, Fmi2Causality.parameter) or \
                s.initial in (Fmi2Initial.exact, Fmi2Initial.approx):
            tattr["start"] = _fmt(s.start)
        if derivative_ref is not None:
            tattr["derivative"] = str(derivative_ref)
        return tattr

    def _initial_unknowns(self) -> list:
        """The variables a master may read in initialization mode that are computed there."""
        initial = {}
        for s in self._specs:
            if s.causality == Fmi2Causality.output and s.initial in (Fmi2Initial.approx, Fmi2Initial.calculated):
                initial[s.index] = s
            if s.causality == Fmi2Causality.calculatedParameter:
                initial[s.index] = s
        for s in self._specs:
            if s.derivative_of:
                for v in (self._by_name[s.derivative_of], s):
                    if v.initial in (Fmi2Initial.approx, Fmi2Initial.calculated):
                        initial[v.index] = v
        return [initial[i] for i in sorted(initial)]

    def _unit_definitions(self, extra=()) -> tuple:
        """(declared types used, <UnitDefinitions> or None): the same element in FMI 2.0 and 3.0
        (`extra`: units used by variables that are not declarations, FMI 3.0's time)."""
        used_types = sorted({s.declared_type for s in self._specs if s.declared_type})
        used_units = {s.unit for s in self._specs if s.unit} | set(extra)
        used_units |= {TYPES[t][1] for t in used_types}
        if not used_units:
            return used_types, None
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
        return used_types, ud

    def _default_experiment_xml(self) -> Optional[Element]:
        de = getattr(self, "default_experiment", None)
        if de is None:
            return None
        attr = {}
        for key, val in (("startTime", de.start_time), ("stopTime", de.stop_time),
                         ("tolerance", de.tolerance), ("stepSize", de.step_size)):
            if val is not None:
                attr[key] = _fmt(float(val))
        return Element("DefaultExperiment", attr)
