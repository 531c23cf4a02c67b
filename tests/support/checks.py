"""Shared checks of the tests: numeric bounds recorded by the run, and plots that show data.

`check(quantity, observed, bound, reason=None)`: asserts |observed| <= bound (an array: its largest
magnitude) and records (test, quantity, observed, bound, reason) for the run. tests/conftest.py writes
the records of a run to tests/tolerances.json and fails the session on a bound more than 10x the observed
error unless `reason` says why the bound cannot be tighter (round-off that differs between platforms, a
measured scatter). The observed value is the run's own, so no comment beside the bound goes stale.

`check_min(quantity, observed, floor, reason=None)`: the lower-bound form, for a quantity that must be
large enough (a run that moved, a count of injected faults): asserts min(observed) >= floor > 0 and
records it the same way; a floor below a tenth of the observed value needs a reason.

`check_png(path, lines=1)`: the file is a PNG of at least 300 x 200 pixels on which the first `lines`
colours of matplotlib's colour cycle (C0, C1, ...; also drawn half transparent) each cover at least
`min_pixels` pixels: data was drawn, not only axes, grid and labels, which are grey or black (an empty or
all-NaN plot fails, which a file-size check lets through).
"""
from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np

#: what check() recorded in this process: dicts of test, quantity, observed, bound, reason
RECORDS: list = []

#: a bound more than this many times the observed error needs a reason
RATIO = 10.0

#: the reason of the convergence-order checks
SECOND_ORDER = ("the error ratio at steps h and h/2 is 4 for a second-order method; +-0.5 tells order 2 from "
                "orders 1 and 3 (ratios 2 and 8), and how close to 4 it comes depends on the steps")


def _test_id() -> str:
    return os.environ.get("PYTEST_CURRENT_TEST", "?").rsplit(" (", 1)[0]


def check(quantity: str, observed, bound: float, reason: str | None = None) -> float:
    """Assert |observed| <= bound and record it; returns the observed magnitude."""
    obs = float(np.max(np.abs(np.asarray(observed, dtype=float)))) if np.size(observed) else 0.0
    caller = sys._getframe(1)
    RECORDS.append({"test": _test_id(), "quantity": quantity, "observed": obs, "bound": float(bound),
                    "reason": reason, "line": f"{os.path.basename(caller.f_code.co_filename)}:{caller.f_lineno}"})
    assert obs <= bound, f"{quantity}: {obs:.3g} > bound {bound:.3g}"      # NaN fails too
    return obs


def check_min(quantity: str, observed, floor: float, reason: str | None = None) -> float:
    """Assert min(observed) >= floor (> 0) and record it; returns the observed minimum."""
    assert floor > 0.0, f"{quantity}: a floor must be positive ({floor!r}); a sign is checked by check()"
    obs = float(np.min(np.asarray(observed, dtype=float)))
    caller = sys._getframe(1)
    RECORDS.append({"test": _test_id(), "quantity": quantity, "observed": obs, "bound": float(floor),
                    "reason": reason, "kind": "min",
                    "line": f"{os.path.basename(caller.f_code.co_filename)}:{caller.f_lineno}"})
    assert obs >= floor, f"{quantity}: {obs:.3g} < floor {floor:.3g}"      # NaN fails too
    return obs


def ratio(rec: dict) -> float:
    """How far the bound is from what the run saw: bound / observed, or observed / floor (inf at 0)."""
    b, o = rec["bound"], rec["observed"]
    if rec.get("kind") == "min":
        return o / b
    return float("inf") if o == 0.0 else b / o


def too_wide(rec: dict) -> bool:
    """A bound more than RATIO x its observed error (or above an exact zero), or a floor below a RATIO-th
    of the observed value, without a reason."""
    if rec.get("reason") or rec["bound"] <= 0.0:
        return False
    return ratio(rec) > RATIO


def check_png(path, lines: int = 1, min_pixels: int = 50) -> None:
    import matplotlib
    import matplotlib.image as mimage
    from matplotlib import colors as mcolors

    path = Path(path)
    assert path.is_file(), f"{path}: missing"
    with open(path, "rb") as fh:
        assert fh.read(8) == b"\x89PNG\r\n\x1a\n", f"{path}: not a PNG"
    img = mimage.imread(path)[..., :3]
    assert img.shape[0] >= 200 and img.shape[1] >= 300, f"{path}: {img.shape[1]} x {img.shape[0]} pixels"
    cycle = matplotlib.rcParams["axes.prop_cycle"].by_key()["color"]
    for name in cycle[:lines]:
        rgb = np.array(mcolors.to_rgb(name))
        # the colour itself or blended with white down to alpha 0.6
        near = [np.abs(img - (a * rgb + (1.0 - a))).max(axis=2) < 0.05 for a in (1.0, 0.9, 0.8, 0.7, 0.6)]
        n = int(np.logical_or.reduce(near).sum())
        assert n >= min_pixels, f"{path}: {n} pixels of the data colour {mcolors.to_hex(name)} (a line or marker needs {min_pixels})"
