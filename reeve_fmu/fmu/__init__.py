"""The FMI layer: FMU machinery, FMU build and the co-simulation masters (the physics lives in core and
components).

* `reeve_fmu.fmu.slave`   -- `ReeveSlave`, the pythonfmu base class of every reeve_fmu FMU entry: the guarded
  FMI state machine (calls, checks, errors, the loader's fast path)
* `reeve_fmu.fmu.description` -- variable declarations, units and types, modelDescription.xml
* `reeve_fmu.fmu.state`   -- FMU state get/set and (de)serialisation
* `reeve_fmu.fmu.build`   -- `build_fmu`, `fmu_is_stale`, `read_stamp`, `current_package_hash`
* `reeve_fmu.fmu.runner`  -- `run_in_subprocess`, `SlaveHandle` (fmpy FMU2Slave wrapper)
* `reeve_fmu.fmu._bootstrap` -- stdlib-only shim that runs inside FMUs (stable numba cache dir)
* `reeve_fmu.fmu.cosim`   -- plant/drive FMU build inputs, the fmpy master `cosimulate`, the monolithic reference
* `reeve_fmu.fmu.native`  -- the C loader put in front of pythonfmu's binary at build time (any FMI host, no
  LD_PRELOAD, clean exit, errors always logged; docs/fmu-hosts.md)
* `reeve_fmu.fmu.container` -- plant + drive as one FMU (fmpy's container FMU)

Names are imported lazily so that `import reeve_fmu.fmu` costs nothing.
"""
from __future__ import annotations

import importlib

_EXPORTS = {
    "ReeveSlave": "slave", "DefaultExperiment": "slave", "Fmi2Status": "slave",
    "build_fmu": "build", "fmu_is_stale": "build", "read_stamp": "build",
    "current_package_hash": "build", "FmuBuildError": "build",
    "run_in_subprocess": "runner", "SlaveHandle": "runner", "SubprocessJobError": "runner",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name):
    mod = _EXPORTS.get(name)
    if mod is None:
        raise AttributeError(f"module 'reeve_fmu.fmu' has no attribute {name!r}")
    return getattr(importlib.import_module(f"{__name__}.{mod}"), name)
