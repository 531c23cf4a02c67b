"""reeve_fmu: ALE rope models of reeving systems exported as FMI 2.0 co-simulation FMUs.

Layers (nothing below imports from above): scene (parse/validate) -> model (compile) -> elements
(kernels) -> solver -> front ends (fmu, cosim, can, analysis, cli).
"""
__version__ = "0.1.0"
