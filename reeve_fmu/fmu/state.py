"""FMU state of a `ReeveSlave`: get/set FMU state and its (de)serialisation.

The snapshot holds *all* of an instance's state (registered values, time, mode, hidden model state)
as a canonical deep copy of builtin types, so an in-memory restore and a JSON (de)serialised restore
are bit-identical; JSON keeps NaN/Inf. `FmuState` is mixed into ReeveSlave (reeve_fmu.fmu.slave).
"""
from __future__ import annotations

import json
import traceback

from pythonfmu.enums import Fmi2Causality, Fmi2Variability

__all__ = ["FmuState", "STATE_FORMAT", "canonical_state"]

STATE_FORMAT = "reeve_fmu.state/1"


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
            tv = type(v)    # a scalar as is, without the call (most of a slave's values: the state's cost)
            out[k] = v if tv is float or tv is int or tv is bool or tv is str or v is None \
                else canonical_state(v, f"{path}.{k}")
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



class FmuState:
    """pythonfmu's FMU state hooks for ReeveSlave (the slave's values, mode and hidden state)."""

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
