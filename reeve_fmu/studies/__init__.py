"""Studies built on the engine and the co-simulation masters.

analysis    trip metrics: EN 81-50 traction, ISO 18738 ride quality, stopping accuracy
trip        the demo's reference trip: scenario constants, traction limits, trip summary
bench       work-precision study (ALE against the Lagrangian baseline) and trip timing
fidelity    pick the cheapest model configuration that meets an accuracy target
crane       quasi-static crane hoist: hook-block rotation, cabling height (continuation)
lagrangian  Lagrangian finite-element baseline (material mesh, contact, friction) and its kernels
snapload    exact wave solution of the emergency-stop snap load (rope with an end mass), lumped-chain check
"""
