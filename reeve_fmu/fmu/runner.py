"""Helpers for tests and masters: FMU jobs in fresh subprocesses, and a thin fmpy FMU2Slave wrapper.

Why subprocesses (docs/cosim.md, 'pythonfmu and fmpy' item 4): pythonfmu FMUs share the host interpreter, so an FMU's entry module,
its embedded packages and pythonfmu itself land in the host's `sys.modules`; two FMUs with the same
module names silently run each other's code, and rarely the process aborts at exit with heap
corruption. So every FMU-loading job runs in its own interpreter and is judged by its result file
*and* its exit code.

`run_in_subprocess(job, *args, timeout=...)`
    job = "package.module:function" or "/path/to/file.py:function" -> function(*args)
          any other string -> Python source executed with `ARGS` bound; it must set `result`.
    args and result travel as JSON (NaN/Inf allowed). Returns the result. Raises
    SubprocessJobError with the child's traceback/stdout/stderr when the job raised, timed out, died
    before writing its result, or exited non-zero, also after writing its result: a crash at exit is
    a failure, never retried (the child skips interpreter finalisation once its result is on disk, so
    a crash there is the job's own).

`SlaveHandle` (context manager)
    h = SlaveHandle.open(fmu_path, "plant")           # extract, instantiate(loggingOn=True)
    h.setup(start_time=0.0, start_values={"cabin.mass": 500.0})   # setup/enter/set/exit init
    h.set("motor.tau", 1500.0); status = h.step(1e-3); x = h.get("cabin.position")
    s = h.get_state(); blob = h.serialize_state(s); h.set_state(h.deserialize_state(blob))
    h.messages  -> [LogMessage(status, category, message)] collected from the FMU logger
    h.close()   -> terminate, freeInstance, remove the extracted directory
"""
from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
from ctypes import byref
from pathlib import Path
from typing import Any, Iterable, NamedTuple, Optional, Sequence, Union

__all__ = ["run_in_subprocess", "SubprocessJobError", "SlaveHandle", "LogMessage", "STATUS_NAMES"]

STATUS_NAMES = ("ok", "warning", "discard", "error", "fatal", "pending")

_FUNC_SPEC = re.compile(r"^(?:[A-Za-z_][\w.]*|.+\.py):[A-Za-z_]\w*$", re.S)

_CHILD = r"""
import json, os, sys, traceback
result_path, spec, args_path = sys.argv[1:4]

def _write(obj):
    tmp = result_path + ".tmp"
    with open(tmp, "w", encoding="utf-8") as fh:
        json.dump(obj, fh, allow_nan=True)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, result_path)

try:
    with open(args_path, encoding="utf-8") as fh:
        args = json.load(fh)
    if spec.startswith("code:"):
        ns = {"__name__": "__reeve_job__", "ARGS": args}
        exec(compile(spec[5:], "<reeve job>", "exec"), ns)
        if "result" not in ns:
            raise RuntimeError("job code did not set the variable 'result'")
        res = ns["result"]
    else:
        target, func = spec.rsplit(":", 1)
        if target.endswith(".py"):
            import importlib.util
            name = "__reeve_job_" + os.path.splitext(os.path.basename(target))[0]
            sp = importlib.util.spec_from_file_location(name, target)
            mod = importlib.util.module_from_spec(sp)
            sys.modules[name] = mod
            sp.loader.exec_module(mod)
        else:
            import importlib
            mod = importlib.import_module(target)
        res = getattr(mod, func)(*args)
    payload = {"status": "ok", "result": res}
    try:
        json.dumps(payload, allow_nan=True)
    except Exception as exc:
        raise TypeError(f"job result is not JSON-serialisable: {exc}") from exc
    _write(payload)
except BaseException:
    _write({"status": "error", "error": traceback.format_exc()})
    sys.stdout.flush(); sys.stderr.flush()
    os._exit(1)
sys.stdout.flush(); sys.stderr.flush()
# The result is on disk: skip interpreter finalisation, where pythonfmu FMUs occasionally corrupt
# the heap at exit (docs/cosim.md, 'pythonfmu and fmpy' item 4, PythonFMU #228; seen here as "corrupted double-linked list").
os._exit(0)
"""

class SubprocessJobError(RuntimeError):
    def __init__(self, msg: str, *, returncode=None, stdout="", stderr="", child_traceback=None):
        self.returncode = returncode
        self.stdout = stdout
        self.stderr = stderr
        self.child_traceback = child_traceback
        parts = [msg]
        if child_traceback:
            parts.append("--- child traceback ---\n" + child_traceback.rstrip())
        if stdout and stdout.strip():
            parts.append("--- child stdout (tail) ---\n" + stdout[-4000:].rstrip())
        if stderr and stderr.strip():
            parts.append("--- child stderr (tail) ---\n" + stderr[-4000:].rstrip())
        super().__init__("\n".join(parts))


def _json_default(o):
    if isinstance(o, os.PathLike):
        return os.fspath(o)
    raise TypeError(f"job argument {o!r} is not JSON-serialisable")


def _repo_root() -> str:
    return str(Path(__file__).resolve().parents[2])


def _run_once(spec: str, args_path: str, workdir: str, timeout: float, env: dict, cwd, python):
    result_path = os.path.join(workdir, "result.json")
    for p in (result_path, result_path + ".tmp"):
        if os.path.exists(p):
            os.unlink(p)
    proc = subprocess.Popen([python, "-c", _CHILD, result_path, spec, args_path], cwd=cwd, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            encoding="utf-8", errors="replace", start_new_session=True)
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        try:
            os.killpg(proc.pid, signal.SIGKILL)  # the child's own session/process group
        except OSError:
            proc.kill()
        out, err = proc.communicate()
        raise SubprocessJobError(f"job timed out after {timeout} s", returncode=proc.returncode,
                                 stdout=out, stderr=err)
    payload = None
    if os.path.exists(result_path):
        try:
            with open(result_path, encoding="utf-8") as fh:
                payload = json.load(fh)
        except ValueError:
            payload = None
    return proc.returncode, payload, out, err


def run_in_subprocess(func_path_or_code: str, *args, timeout: float = 120.0,
                      env: Optional[dict] = None, cwd: Union[str, Path, None] = None,
                      python: Optional[str] = None) -> Any:
    """Run an FMU-loading job in a fresh interpreter and return its JSON result (see module doc)."""
    if _FUNC_SPEC.match(func_path_or_code.strip()) and "\n" not in func_path_or_code.strip():
        spec = func_path_or_code.strip()
    else:
        spec = "code:" + func_path_or_code
    child_env = dict(os.environ if env is None else env)
    root = _repo_root()
    pp = child_env.get("PYTHONPATH", "")
    child_env["PYTHONPATH"] = root + (os.pathsep + pp if pp else "")
    child_env.setdefault("PYTHONFAULTHANDLER", "1")
    python = python or sys.executable
    with tempfile.TemporaryDirectory(prefix="reeve_job_") as workdir:
        if env is None or "TMPDIR" not in env:
            # the child's temporary files (fmpy.extract's unpacked FMUs: ~5 MB each) go with the job:
            # a job ends without interpreter finalisation, so nothing in it would remove them
            child_env["TMPDIR"] = os.path.join(workdir, "tmp")
            os.mkdir(child_env["TMPDIR"])
        args_path = os.path.join(workdir, "args.json")
        with open(args_path, "w", encoding="utf-8") as fh:
            json.dump(list(args), fh, allow_nan=True, default=_json_default)
        rc, payload, out, err = _run_once(spec, args_path, workdir, timeout, child_env, cwd, python)
    if payload is not None and payload.get("status") == "error":
        raise SubprocessJobError("job raised an exception", returncode=rc, stdout=out,
                                 stderr=err, child_traceback=payload.get("error"))
    if payload is None:
        raise SubprocessJobError(f"job died without writing its result (exit code {rc})",
                                 returncode=rc, stdout=out, stderr=err)
    if rc != 0:
        raise SubprocessJobError(f"job wrote its result but exited with code {rc}", returncode=rc,
                                 stdout=out, stderr=err)
    return payload["result"]


# ==================================================================================================
# fmpy FMU2Slave wrapper
# ==================================================================================================
class LogMessage(NamedTuple):
    status: int
    category: str
    message: str
    instance: str

    @property
    def status_name(self) -> str:
        return STATUS_NAMES[self.status] if 0 <= self.status < len(STATUS_NAMES) else str(self.status)

    def __str__(self):
        return f"[{self.status_name.upper()}] {self.message}"


#: FMI 3.0 variable types -> the FMI 2.0 names this wrapper dispatches on
_FMI3_TYPES = {"Float64": "Real", "Int32": "Integer", "Boolean": "Boolean", "String": "String"}


class SlaveHandle:
    """One FMU2Slave (or, for an FMI 3.0 FMU, FMU3Slave) instance with name-based access, collected log
    messages and cleanup. FMI 3.0: `early_return` instantiates with earlyReturnAllowed and
    eventModeUsed (the FMU's Event Mode is entered by `handle_event` after an early return); `fmi3`
    tells the version; `last_step` holds fmi3DoStep's (eventHandlingNeeded, terminateSimulation,
    earlyReturn, lastSuccessfulTime) of do_step."""

    def __init__(self, fmu_path: Union[str, Path], instance_name: str = "instance", *,
                 logging_on: bool = True, echo: bool = False, unzip_dir: Union[str, Path, None] = None,
                 early_return: bool = False):
        from fmpy import extract, read_model_description

        self.path = Path(fmu_path)
        self.instance_name = instance_name
        self.md = read_model_description(str(self.path))
        self.fmi3 = self.md.fmiVersion.startswith("3")
        self.early_return = bool(early_return and self.fmi3)
        self.last_step = None
        self._owns_dir = unzip_dir is None
        self.unzip_dir = str(unzip_dir) if unzip_dir is not None else str(extract(str(self.path)))
        self.variables = {v.name: v for v in self.md.modelVariables}
        self._vr = {v.name: (_FMI3_TYPES.get(v.type, v.type) if self.fmi3 else v.type, v.valueReference)
                    for v in self.md.modelVariables}
        self.messages: list[LogMessage] = []
        self.echo = echo
        self.time: Optional[float] = None
        self._fmu = None
        self._instantiated = False
        self._initialized = False
        self._terminated = False
        self._closed = False
        self._logging_on = logging_on

    # -- construction -------------------------------------------------------------------------
    @classmethod
    def open(cls, fmu_path, instance_name: str = "instance", *, logging_on: bool = True,
             echo: bool = False, unzip_dir=None, early_return: bool = False) -> "SlaveHandle":
        h = cls(fmu_path, instance_name, logging_on=logging_on, echo=echo, unzip_dir=unzip_dir,
                early_return=early_return)
        try:
            h.instantiate()
        except BaseException:
            h.close()
            raise
        return h

    def _record(self, status, category, message, instance) -> None:
        try:
            msg = LogMessage(int(status), category.decode("utf-8", "replace") if category else "",
                             message.decode("utf-8", "replace") if message else "",
                             instance.decode("utf-8", "replace") if instance else "")
            self.messages.append(msg)
            if self.echo:
                print(str(msg), file=sys.stderr)
        except Exception:  # pragma: no cover - never raise into C
            pass

    def _make_callbacks(self):
        from fmpy.fmi2 import (fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                               fmi2CallbackFunctions, fmi2CallbackLoggerTYPE)
        from fmpy.fmi1 import calloc, free

        def _logger(component, instance, status, category, message):
            self._record(status, category, message, instance)

        cb = fmi2CallbackFunctions()
        cb.logger = fmi2CallbackLoggerTYPE(_logger)
        cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        cb.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        try:
            from fmpy.logging import addLoggerProxy  # formats the printf-style message in C

            addLoggerProxy(byref(cb))
        except Exception:  # pragma: no cover
            pass
        self._cb_keepalive = (_logger, cb)
        return cb

    def instantiate(self):
        from fmpy.fmi2 import FMU2Slave
        from fmpy.fmi3 import FMU3Slave

        self._fmu = (FMU3Slave if self.fmi3 else FMU2Slave)(
            guid=self.md.guid, unzipDirectory=self.unzip_dir, modelIdentifier=self.md.coSimulation.modelIdentifier,
            instanceName=self.instance_name)
        try:
            if self.fmi3:
                name = self.instance_name.encode("utf-8")
                self._fmu.instantiate(loggingOn=self._logging_on, eventModeUsed=self.early_return,
                                      earlyReturnAllowed=self.early_return,
                                      logMessage=lambda env, st, cat, msg: self._record(st, cat, msg, name))
            else:
                self._fmu.instantiate(callbacks=self._make_callbacks(), loggingOn=self._logging_on)
        except Exception as exc:
            # fmpy only says "Failed to instantiate model"; the cause is in the FMU's log
            raise RuntimeError(f"{'fmi3InstantiateCoSimulation' if self.fmi3 else 'fmi2Instantiate'} of "
                               f"{self.path.name} ({self.instance_name!r}) "
                               f"failed: {exc}\n" + (self.log_text() or
                                                     "(no log messages; use logging_on=True)")
                               ) from exc
        self._instantiated = True

    @property
    def fmu(self):
        """The underlying fmpy FMU2Slave (FMU3Slave)."""
        return self._fmu

    def setup(self, start_time: float = 0.0, stop_time: Optional[float] = None,
              tolerance: Optional[float] = None, start_values: Optional[dict] = None,
              initialize: bool = True) -> None:
        """setupExperiment, enterInitializationMode, set start values, exitInitializationMode (FMI 3.0:
        enterInitializationMode with the times, ...; with eventModeUsed then Event Mode is left at once:
        fmi3UpdateDiscreteStates, fmi3EnterStepMode)."""
        f = self._fmu
        if self.fmi3:
            f.enterInitializationMode(tolerance=tolerance, startTime=start_time, stopTime=stop_time)
        else:
            f.setupExperiment(tolerance=tolerance, startTime=start_time, stopTime=stop_time)
            f.enterInitializationMode()
        if start_values:
            self.set_many(start_values)
        if initialize:
            f.exitInitializationMode()
            self._initialized = True
            if self.early_return:
                f.updateDiscreteStates()
                f.enterStepMode()
        self.time = start_time

    def handle_event(self) -> None:
        """FMI 3.0 with eventModeUsed, after a step that returned eventHandlingNeeded: Event Mode (the
        inputs may be set there), fmi3UpdateDiscreteStates until nothing is left to update, Step Mode."""
        f = self._fmu
        f.enterEventMode()
        while f.updateDiscreteStates()[0]:
            pass
        f.enterStepMode()

    # -- variables ------------------------------------------------------------------------------
    def _ref(self, name: str):
        try:
            return self._vr[name]
        except KeyError:
            raise KeyError(f"{self.path.name} has no variable {name!r}; its inputs: "
                           f"{[v.name for v in self.md.modelVariables if v.causality == 'input']}") from None

    def vr(self, name: str) -> int:
        return self._ref(name)[1]

    def set(self, name: str, value) -> None:
        typ, vr = self._ref(name)
        f = self._fmu
        if typ == "Real":
            (f.setFloat64 if self.fmi3 else f.setReal)([vr], [float(value)])
        elif typ == "Integer" or typ == "Enumeration":
            (f.setInt32 if self.fmi3 else f.setInteger)([vr], [int(value)])
        elif typ == "Boolean":
            f.setBoolean([vr], [bool(value)])
        else:
            f.setString([vr], [str(value)])

    def set_many(self, values: dict) -> None:
        for name, value in values.items():
            self.set(name, value)

    def get(self, name: str):
        typ, vr = self._ref(name)
        f = self._fmu
        if typ == "Real":
            return (f.getFloat64 if self.fmi3 else f.getReal)([vr])[0]
        if typ == "Integer" or typ == "Enumeration":
            return (f.getInt32 if self.fmi3 else f.getInteger)([vr])[0]
        if typ == "Boolean":
            return bool(f.getBoolean([vr])[0])
        v = f.getString([vr])[0]
        return v.decode("utf-8") if isinstance(v, bytes) else v

    def get_many(self, names: Sequence[str]) -> list:
        reals = [n for n in names if self._vr[n][0] == "Real"]
        out = {}
        if reals:
            get = self._fmu.getFloat64 if self.fmi3 else self._fmu.getReal
            out.update(zip(reals, get([self._vr[n][1] for n in reals])))
        for n in names:
            if n not in out:
                out[n] = self.get(n)
        return [out[n] for n in names]

    def get_dict(self, names: Optional[Iterable[str]] = None) -> dict:
        names = list(self._vr) if names is None else list(names)
        return dict(zip(names, self.get_many(names)))

    # -- stepping -------------------------------------------------------------------------------
    def do_step(self, t: float, dt: float) -> int:
        """fmi2DoStep (fmi3DoStep: its out-arguments in last_step); returns the status code (0 ok, 1
        warning, 2 discard, 3 error, 4 fatal)."""
        from fmpy.fmi1 import FMICallException

        try:
            r = self._fmu.doStep(currentCommunicationPoint=t, communicationStepSize=dt)
            if self.fmi3:
                self.last_step = r
        except FMICallException as e:
            return int(e.status)
        return 0

    def step(self, dt: float) -> int:
        """do_step from the handle's current time; advances the time only on success."""
        t = 0.0 if self.time is None else self.time
        status = self.do_step(t, dt)
        if status <= 1:
            self.time = t + dt
        return status

    # -- state ----------------------------------------------------------------------------------
    def get_state(self):
        return self._fmu.getFMUState() if self.fmi3 else self._fmu.getFMUstate()

    def set_state(self, state, time: Optional[float] = None) -> None:
        (self._fmu.setFMUState if self.fmi3 else self._fmu.setFMUstate)(state)
        if time is not None:
            self.time = time

    def free_state(self, state) -> None:
        (self._fmu.freeFMUState if self.fmi3 else self._fmu.freeFMUstate)(state)

    def serialize_state(self, state) -> bytes:
        return (self._fmu.serializeFMUState if self.fmi3 else self._fmu.serializeFMUstate)(state)

    def deserialize_state(self, blob: bytes):
        return (self._fmu.deserializeFMUState if self.fmi3 else self._fmu.deSerializeFMUstate)(blob)

    def reset(self) -> None:
        self._fmu.reset()
        self._initialized = False
        self._terminated = False
        self.time = None

    # -- messages -------------------------------------------------------------------------------
    def errors(self, min_status: int = 3) -> list:
        return [m for m in self.messages if m.status >= min_status]

    def log_text(self) -> str:
        return "\n".join(str(m) for m in self.messages)

    # -- teardown -------------------------------------------------------------------------------
    def terminate(self) -> None:
        if self._instantiated and not self._terminated:
            self._terminated = True
            self._fmu.terminate()

    def close(self) -> None:
        """terminate (if initialized) + freeInstance + remove the extracted directory. Idempotent."""
        if self._closed:
            return
        self._closed = True
        try:
            if self._instantiated:
                try:
                    if self._initialized and not self._terminated:
                        self.terminate()
                finally:
                    self._instantiated = False
                    self._fmu.freeInstance()
        finally:
            if self._owns_dir and self.unzip_dir:
                shutil.rmtree(self.unzip_dir, ignore_errors=True)

    def __enter__(self) -> "SlaveHandle":
        if not self._instantiated and not self._closed:
            self.instantiate()
        return self

    def __exit__(self, *exc) -> None:
        self.close()
