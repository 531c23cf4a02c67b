"""Results: the one time-series type, CSV with the documented output names, and overview plots."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np


@dataclass
class TimeSeries:
    """Sampled signals: `time` [s] and `columns` {output name: numpy array in SI units}; `info` (how the
    run went: master, steps, walls, monitor report) and `summary` (metrics and verdicts, for trips).
    `ts["car.position"]`, `ts["time"]`; `to_csv(path)` writes the CSV every front end writes."""
    time: np.ndarray
    columns: dict
    info: dict = field(default_factory=dict)
    summary: dict = field(default_factory=dict)

    def __getitem__(self, name: str) -> np.ndarray:
        if name == "time":
            return self.time
        return self.columns[name]

    def names(self) -> list:
        return list(self.columns)

    def as_dict(self) -> dict:
        d = {"time": self.time}
        d.update(self.columns)
        return d

    def to_csv(self, path) -> Path:
        return write_csv(path, self.time, self.columns)

    def to_pandas(self):
        """A pandas DataFrame indexed by time [s] (needs pandas)."""
        try:
            import pandas as pd
        except ImportError:
            raise ImportError("to_pandas needs pandas: pip install pandas") from None
        return pd.DataFrame(self.columns, index=pd.Index(self.time, name="time"))


def write_csv(path, time, columns: dict):
    """CSV with a `time` column first, then the named columns (SI units, '%.10g'); values with
    |x| < 1e-300 (denormals, solver round-off of a zero) are written as 0."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    names = list(columns)
    data = np.column_stack([np.asarray(time, float)] + [np.asarray(columns[n], float) for n in names])
    data[np.abs(data) < 1e-300] = 0.0
    header = ",".join(["time"] + names)
    np.savetxt(path, data, delimiter=",", header=header, comments="", fmt="%.10g", encoding="utf-8")
    return path


def read_csv(path) -> dict:
    data = np.genfromtxt(path, delimiter=",", names=True, deletechars="", dtype=float, encoding="utf-8")
    return {n: np.asarray(data[n]) for n in data.dtype.names}


def plot_overview(path, time, columns: dict, title: str = "", event=None):
    """Body motion, sheave tensions and traction ratio, motor torque: one PNG. event = (time, cause)
    of a run stopped early: a red line at that time on every panel."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    groups = [
        ("position [m]", [n for n in columns if ".position" in n]),
        ("velocity [m/s]", [n for n in columns if ".velocity" in n]),
        ("acceleration [m/s²]", [n for n in columns if ".acceleration" in n]),
        ("rope tension [N]", [n for n in columns if ".tension_" in n and not n.startswith(tuple(
            r for r in []))]),
        ("traction ratio [-]", [n for n in columns if n.endswith(".traction_ratio")]),
        ("motor torque [N·m]", [n for n in columns if n == "motor.torque"]),
    ]
    groups = [(lab, names) for lab, names in groups if names]
    fig, axes = plt.subplots(len(groups), 1, figsize=(10, 2.3 * len(groups)), sharex=True)
    axes = np.atleast_1d(axes)
    for ax, (lab, names) in zip(axes, groups):
        for n in names:
            y = np.asarray(columns[n], float)
            ax.plot(time, np.where(np.isfinite(y), y, np.nan), lw=0.9, label=n)
        if lab.startswith("traction ratio"):
            lab += _clip_ratio_axis(ax, [columns[n] for n in names])
        ax.set_ylabel(lab)
        ax.grid(True, alpha=0.3)
        if event is not None:
            ax.axvline(event[0], color="red", lw=1.2, ls="--")
        if len(names) <= 12:
            ax.legend(fontsize=7, loc="best", ncol=2 if len(names) > 4 else 1)
    axes[-1].set_xlabel("time [s]")
    if event is not None:
        title = f"{title}\nstopped at t = {event[0]:.4f} s: {event[1]}".strip()
    if title:
        axes[0].set_title(title, fontsize=9 if event is not None else None)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def _clip_ratio_axis(ax, arrays) -> str:
    """A slack rope sends T1/T2 towards 1e5; limit the axis to the 99.5th percentile (and at least 1..2)
    so the operating range stays readable. Returns a label suffix when clipped."""
    y = np.concatenate([np.asarray(a, float) for a in arrays])
    y = y[np.isfinite(y)]
    if not y.size:
        return ""
    hi = max(float(np.percentile(y, 99.5)), 2.0)
    if float(np.max(y)) <= 1.1 * hi:
        return ""
    ax.set_ylim(min(1.0, float(np.min(y))) - 0.05, 1.1 * hi)
    return f"\n(clipped; max {float(np.max(y)):.3g})"
