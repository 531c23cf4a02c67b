"""Integrators for M(q) qdd = Q(q, qdot, t, u) and the static equilibrium (docs/theory.md §4.7).

After the linear constraints are eliminated (p = B q + c, model.py) the equations are an ODE of index
0 in q: no multipliers, no drift. Prescribed coordinates (a speed-driven sheave) are rheonomic: they
are set from the profile and their rows give the drive torque (reaction).

Methods (one protocol, `Simulator.advance`):
  gen-alpha   Chung-Hulbert generalized-alpha in the Arnold-Bruls form, fixed step, Newton on the
              free accelerations with a finite-difference Newton matrix kept across steps (modified
              Newton; refreshed when convergence slows or the step changes). rho_inf in [0, 1] sets the
              numerical dissipation of the stiff, unresolved axial modes; rho_inf = 1 is the
              non-dissipative trapezoidal limit used by the energy tests. The whole stepping loop is
              compiled (numba), so a step costs a few microseconds.
  radau       scipy's Radau IIA (stiff, adaptive): reference solutions.
  dop853      scipy's explicit 8th order: reference for non-stiff tests (energy drift).

Modules:
  genalpha    the method's parameters, Newmark relations and Newton exit test (shared with the
              Lagrangian baseline, studies/lagrangian_kernels.py)
  lu          small dense LU (compiled)
  newton      one generalized-alpha step: residual, Newton matrix (dense or banded), iteration
  stepping    the compiled stepping loop (substeps, brake, traction and creep updates, outputs)
  statics     static equilibrium, preloads, consistent accelerations
  scipy_path  the scipy reference methods
  inputs      the kernels' inputs and outputs at a State
  result      Result, SolverError, status texts
  simulator   the Simulator: settings over the above
"""
from .genalpha import gen_alpha_params
from .newton import SPARSE_MIN_FREE
from .result import STATUS_TEXT, Result, SolverError
from .simulator import Simulator

__all__ = ["SPARSE_MIN_FREE", "STATUS_TEXT", "Result", "Simulator", "SolverError", "gen_alpha_params"]
