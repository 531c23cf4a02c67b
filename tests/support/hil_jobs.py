"""Jobs for tests/hil/test_hil.py that load the plant FMU, each run in a fresh interpreter by
reeve_fmu.fmu.runner.run_in_subprocess (one process per FMU-loading job, docs/cosim.md, 'pythonfmu and fmpy' item 4). Results travel as
JSON (floats exactly)."""
import os


def hil_run(config: dict, columns=("car.position",)) -> dict:
    """run_hil with the given HilConfig fields; returns the summary and the requested result columns."""
    import numpy as np

    from reeve_fmu.hil.runners import HilConfig, run_hil
    from reeve_fmu.core.results import read_csv

    summary = run_hil(HilConfig(**config), log=None)
    out = {"summary": summary}
    if config.get("out") and columns:
        c = read_csv(os.path.join(config["out"], "results.csv"))
        out["columns"] = {n: np.asarray(c[n]).tolist() for n in ("time",) + tuple(columns)}
    return out
