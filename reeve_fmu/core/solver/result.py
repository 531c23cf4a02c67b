"""What a run returns and how it fails: Result (sampled outputs), SolverError and the texts of the
compiled step's status codes."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


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


@dataclass
class Result:
    time: np.ndarray
    values: np.ndarray           # (n_samples, n_outputs)
    names: tuple

    def __getitem__(self, name):
        return self.values[:, self.names.index(name)]

    def as_dict(self):
        d = {"time": self.time}
        d.update({n: self.values[:, i] for i, n in enumerate(self.names)})
        return d

