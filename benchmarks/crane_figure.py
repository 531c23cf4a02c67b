"""The figure of docs/crane.md: hook-block yaw against the fall length.

    python benchmarks/crane_figure.py [--out docs/crane_rotation.png]      (≈ 1 min with a warm cache)

Left: `scenes/crane_two_fall.toml` (torque-factor law, GJ = 0) against the closed form
sin psi = 4 k d h/(a b) (docs/theory.md §5.3). Right: `scenes/crane_8fall.toml` with its low-rotation
rope (k0 = 0.006) and with a 6-strand rope (k0 = 0.08), both with the scene's Costello law and GJ0.
"""
import argparse
from pathlib import Path

import numpy as np

from reeve_fmu.studies.crane import load_crane, sweep

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(ROOT / "docs" / "crane_rotation.png"))
    args = ap.parse_args(argv)
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4))
    two = sweep(load_crane(ROOT / "scenes" / "crane_two_fall.toml"))
    m, s = two.crane, two.crane.scene.ropes[0].torsion
    h, psi = two.path[:, 0], two.path[:, 1]
    a1.plot(h, np.degrees(psi), lw=2, label="statics of the model, torque-factor law, GJ = 0")
    hh = np.linspace(h[0], m.H_est, 400)
    a1.plot(hh, np.degrees(np.arcsin(hh / m.H_est)), "k--", lw=1, label="sin ψ = 4kdh/(ab)")
    a1.axvline(two.critical_height, color="r", lw=0.8)
    a1.annotate(f"fold {two.critical_height:.3f} m\n(ab/4kd = {m.H_est:.3f} m)", (two.critical_height, 5),
                color="r", fontsize=8, xytext=(3, 0), textcoords="offset points")
    a1.set_title(f"two falls, d = {s.diameter * 1e3:g} mm, k = {s.k0:g}", fontsize=10)
    a1.set_xlim(0, m.spec.height_max)

    for k0, what in ((None, "low-rotation"), (0.08, "6-strand")):
        six = {"rope.torsion": {"law": "costello", "diameter": 0.022, "k0": k0, "GJ0": 100.0}} if k0 else None
        res = sweep(load_crane(ROOT / "scenes" / "crane_8fall.toml", six))
        sp = res.crane.scene.ropes[0].torsion
        tag = (f"cabling at {res.critical_height:.1f} m" if res.critical_height is not None else "no cabling")
        a2.plot(res.path[:, 0], np.degrees(res.path[:, 1]), lw=2, label=f"k0 = {sp.k0:g} ({what}): {tag}")
        if res.critical_height is not None:
            a2.axvline(res.critical_height, color="r", lw=0.8)
    mm = res.crane
    a2.set_title(f"{len(mm.falls)} falls, {mm.weight / 9.81e3:.0f} t, Ø{sp.diameter * 1e3:g} mm, "
                 f"S_eff = {mm.S_eff:.2f} m, Costello GJ0 = {sp.GJ0:g} N m²", fontsize=10)
    a2.set_xlim(mm.spec.height_min, mm.spec.height_max)
    for a in (a1, a2):
        a.set_xlabel("fall length h [m]")
        a.set_ylabel("block yaw ψ [deg]")
        a.grid(True, alpha=0.3)
        a.legend(fontsize=8, loc="upper left")
    fig.tight_layout()
    fig.savefig(args.out, dpi=100)
    print(f"-> {args.out}")


if __name__ == "__main__":
    main()
