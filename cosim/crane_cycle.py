"""Hoist-and-slew cycle of the slewing crane: CranePlant.fmu + CraneDrive.fmu through the fmpy master.

    python cosim/crane_cycle.py [--scene scenes/slewing_crane.toml] [--fmus DIR] [--slew-input speed]
                                [--step 5e-3] [--t-end 30] [--png docs/img/crane_cosim_sway.png]

Builds both FMUs into DIR (default $REEVE_FMU_FMUS, else fmus/) from the scene, sizes the drive from the
scene (reeve_fmu.components.cranedrive.crane_drive_defaults: the scene's hoist and slew S-curves as references, the
holding torque as pre-torque), co-simulates with reeve_fmu.fmu.crane.cosimulate_crane and plots the
payload sway (swing angles, slew speed, hoist motor torque). The FMUs run Python inside this process:
run it in a fresh interpreter (it is a script, so it is).
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default=str(ROOT / "scenes" / "slewing_crane.toml"))
    ap.add_argument("--fmus", default=os.environ.get("REEVE_FMU_FMUS") or str(ROOT / "fmus"))
    ap.add_argument("--slew-input", choices=("speed", "torque"), default="speed")
    ap.add_argument("--step", type=float, default=5e-3)
    ap.add_argument("--t-end", type=float, default=30.0)
    ap.add_argument("--png", default=str(ROOT / "docs" / "img" / "crane_cosim_sway.png"))
    a = ap.parse_args(argv)
    sys.path.insert(0, str(ROOT))
    from reeve_fmu.fmu.crane import build_crane_fmus, cosimulate_crane

    t0 = time.perf_counter()
    plant, drive, values = build_crane_fmus(a.fmus, a.scene)
    print(f"built {plant.name}, {drive.name} in {a.fmus} ({time.perf_counter() - t0:.1f} s)")
    t0 = time.perf_counter()
    res = cosimulate_crane(plant, drive, step=a.step, t_end=a.t_end, slew_input=a.slew_input, drive_values=values)
    print(f"co-simulated {a.t_end:g} s in {time.perf_counter() - t0:.1f} s wall "
          f"(step {a.step:g} s, slew input {a.slew_input})")
    import numpy as np

    for name in ("payload.swing_radial", "payload.swing_tangential"):
        x = res[name]
        print(f"{name}: max |.| = {np.degrees(np.abs(x).max()):.3f} deg, at the end {np.degrees(x[-1]):.3f} deg")
    plot(res, a.png, a.slew_input)
    print(f"wrote {a.png}")
    return 0


def plot(res, png, slew_input):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    t = res.time
    fig, ax = plt.subplots(3, 1, figsize=(8, 7.5), sharex=True)
    ax[0].plot(t, np.degrees(res["payload.swing_radial"]), label="radial (outwards)")
    ax[0].plot(t, np.degrees(res["payload.swing_tangential"]), label="tangential (slew direction)")
    ax[0].set_ylabel("payload swing [deg]")
    ax[0].legend(loc="best")
    ax[1].plot(t, res["jib.angular_velocity"], label="jib speed")
    ax[1].plot(t, res[f"slew.{slew_input}"] if slew_input == "speed" else res["jib.angular_velocity"] * np.nan,
               "--", label="slew speed command")
    ax[1].set_ylabel("slew speed [rad/s]")
    ax[1].legend(loc="best")
    ax[2].plot(t, res["motor.torque"] / 1e3, label="hoist motor torque")
    ax[2].plot(t, res["jib.joint_torque"] / 1e5, label="slew joint torque / 100")
    ax[2].set_ylabel("torque [kN m]")
    ax[2].set_xlabel("time [s]")
    ax[2].legend(loc="best")
    fig.suptitle("slewing crane, hoist + slew cycle: CranePlant.fmu + CraneDrive.fmu (fmpy)")
    fig.tight_layout()
    Path(png).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png, dpi=90)


if __name__ == "__main__":
    sys.exit(main())
