"""Rope element kernels, one element type per file: linear (1D/2D/3D), cubic ANCF (2D/3D), torsion."""
