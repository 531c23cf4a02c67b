"""Studies built on the engine and the co-simulation masters.

analysis    trip metrics: EN 81-50 traction, ISO 18738 ride quality, stopping accuracy
trip        elevator trips of any elevator scene: case (sized drive, landings, load), run, summary
verdicts    PASS/WARN/FAIL checks against EN 81-20/-50 limits, drive limits, ride targets
overrides   --set KEY=VALUE: dotted scene keys, drive parameters, load
report      thinned CSV/Parquet, trip plots, one-page Markdown report
sweep       grid/list studies of trips on Dask, Parquet results
bench       work-precision study (ALE against the Lagrangian baseline) and trip timing
fidelity    pick the cheapest model configuration that meets an accuracy target
crane       crane hoist sweep on the dynamic model's statics: hook-block rotation, cabling height (continuation)
lagrangian  Lagrangian finite-element baseline (material mesh, contact, friction) and its kernels
snapload    exact wave solution of the emergency-stop snap load (rope with an end mass), lumped-chain check
"""
