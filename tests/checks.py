"""Shared checks of the tests: plots that show data.

`check_png(path, lines=1)`: the file is a PNG of at least 300 x 200 pixels on which the first `lines`
colours of matplotlib's colour cycle (C0, C1, ...; also drawn half transparent) each cover at least
`min_pixels` pixels: data was drawn, not only axes, grid and labels, which are grey or black (an empty or
all-NaN plot fails, which a file-size check lets through).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np


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
