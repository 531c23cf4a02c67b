"""reeve_fmu: ALE rope models of reeving systems exported as FMI 2.0 co-simulation FMUs.

Layers (nothing below imports from above): core (scene, model, elements, solver) -> components (plant,
drive, crane plant and drive, elevator sizing) -> fmu (FMU machinery, co-simulation masters) -> studies
(trips, verdicts, sweeps, bench, fidelity, crane) -> hil -> front ends (cli, demo, api). The scripting
API (docs/api.md) — `simulate`, `cosimulate`, `TimeSeries` and the exceptions a caller catches — is imported
on first use.
"""
__version__ = "0.1.0"

#: public name -> module that defines it (imported on first access: `import reeve_fmu` stays cheap)
_EXPORTS = {
    "simulate": "api", "cosimulate": "api", "TimeSeries": "core.results",
    "SceneError": "core.scene", "PlausibilityError": "core.plausibility", "SolverError": "core.solver",
    "OverrideError": "studies.overrides", "CosimError": "fmu.master", "CosimInstability": "fmu.cosim",
}

__all__ = list(_EXPORTS)


def __getattr__(name):
    if name in _EXPORTS:
        import importlib

        return getattr(importlib.import_module(f"{__name__}.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module 'reeve_fmu' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(__all__))
