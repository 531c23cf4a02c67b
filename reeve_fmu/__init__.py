"""reeve_fmu: ALE rope models of reeving systems exported as FMI 2.0 co-simulation FMUs.

Layers (nothing below imports from above): core (scene, model, elements, solver, plant, drive) -> fmu
(FMU machinery, co-simulation masters) -> studies (trips, verdicts, sweeps, bench, fidelity, crane) ->
hil -> front ends (cli, demo, api). `reeve_fmu.simulate` and `reeve_fmu.cosimulate` are the scripting
API (reeve_fmu.api), imported on first use.
"""
__version__ = "0.1.0"

__all__ = ["simulate", "cosimulate", "Result"]


def __getattr__(name):
    if name in __all__:
        from . import api
        return getattr(api, name)
    raise AttributeError(f"module 'reeve_fmu' has no attribute {name!r}")
