"""What a run returns and how it fails: Result (sampled outputs), SolverError and the texts of the
compiled step's status codes."""
from __future__ import annotations

import numpy as np

from ..results import TimeSeries


class SolverError(RuntimeError):
    """The integration cannot continue; the message says why and when. A run that stops keeps what
    it computed: `result` holds the outputs up to the last good step (Simulator.advance with out_dt,
    Simulator.run), `time` that step's time (None for a failure before the first step, e.g. statics)."""
    result = None
    time = None


STATUS_TEXT = {
    1: "Newton iteration did not converge",
    2: "a rope span reached the minimum material length (vanishing span)",
    3: "non-finite value in the state (NaN/Inf)",
    4: "a drum has no stored rope left",
}


class Result(TimeSeries):
    """A Simulator run's outputs: the TimeSeries every master returns (`res["car.position"]`,
    `to_csv`, `to_pandas`), also held as one array `values` (n_samples, n_outputs) in the order of
    `names` (the columns are views of it)."""

    def __init__(self, time: np.ndarray, values: np.ndarray, names):
        names = tuple(names)
        super().__init__(time, {n: values[:, i] for i, n in enumerate(names)})
        self.values = values
        self.names = names
