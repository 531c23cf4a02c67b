"""The slewing jib crane (scenes/slewing_crane.toml) in dynamics against exact results: static payload
tension M g, the first axial frequency against beta tan beta = rho A L / M, the payload's swing and
rocking frequencies against the rope + rigid block double pendulum, and a short slew-and-hoist run."""
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from reeve_fmu.core.model import build_model
from reeve_fmu.core.profiles import scurve
from reeve_fmu.core.scene import load_scene
from reeve_fmu.core.solver import Simulator

sys.path.insert(0, str(Path(__file__).resolve().parent))
from linearise import linearised  # noqa: E402

G = 9.81
M, I_SWING, D = 2500.0, 2500.0 * (1.0 + 0.64) / 12.0, 0.4   # box 1.0 x 1.0 x 0.8 m, anchor 0.4 m above


@pytest.fixture(scope="module")
def crane():
    m = build_model(load_scene("scenes/slewing_crane.toml"))
    sim = Simulator(m)
    return m, sim, sim.initial_state()


def _modes(sim, st):
    """omega^2 of the linearised free coordinates at rest (K = -dQ/dq, central differences)."""
    Mf, Kf = linearised(sim, st)
    return np.sort(np.linalg.eigvals(np.linalg.solve(Mf, Kf)).real)


def test_static_payload_tension_is_M_g(crane):
    m, sim, st = crane
    y = dict(zip(m.output_names, sim.outputs(st)))
    assert abs(y["hoist.tension_end"] / (M * G) - 1.0) < 1e-7           # measured 2.1e-8
    assert max(abs(y[f"payload.rotation.{c}"]) for c in "xy") < 1e-9     # measured 1.4e-10


def test_axial_and_pendulum_frequencies(crane):
    m, sim, st = crane
    w2 = _modes(sim, st)
    y = dict(zip(m.output_names, sim.outputs(st)))
    # axial: the free spans from the reel to the payload carrying M; their material length (the W1
    # wraps hold R x wrap angle of rope that does not stretch: with them L would be 1.7 % longer)
    K = m.K
    s = [st.c[K.el_idx[ie, a]] + K.el_coef[ie, a] @ st.q[K.el_map[ie, a]] for ie in range(3) for a in (-2, -1)]
    L = sum(s[2 * ie + 1] - s[2 * ie] for ie in range(3))
    rhoA, EA = 1.1, 30e6
    ratio = rhoA * L / M
    beta = math.sqrt(ratio)
    for _ in range(50):
        beta -= (beta * math.tan(beta) - ratio) / (math.tan(beta) + beta / math.cos(beta) ** 2)
    w_axial = beta * math.sqrt(EA / rhoA) / L
    k = int(np.argmin(np.abs(np.sqrt(np.abs(w2)) / w_axial - 1.0)))
    assert abs(math.sqrt(w2[k]) / w_axial - 1.0) < 6e-4                 # measured 8.2e-5
    # swing + rocking, in and across the jib plane: the double pendulum from the tip tangent point
    l = 21.0 - (y["payload.position.z"] + D)
    m_r = rhoA * l
    Mm = np.array([[(M + m_r / 3) * l * l, M * l * D], [M * l * D, M * D * D + I_SWING]])
    Kk = np.array([[(M + m_r / 2) * G * l, 0.0], [0.0, M * G * D]])
    exact = np.sort(np.linalg.eigvals(np.linalg.solve(Mm, Kk)).real)
    assert abs(w2[0]) < 1e-10 * w2[1]                             # yaw: free (no rope torsion here)
    err = np.abs(np.sqrt(w2[1:5] / np.repeat(exact, 2)) - 1.0)
    assert np.all(err < 7e-5), err                                 # measured 2.2e-5, 1.9e-6, 2.4e-7, 3.3e-6


def test_slew_and_hoist_run(crane):
    m, sim, st = crane
    st = st.copy()
    res = sim.run(t_end=3.0, out_dt=0.05, state=st)
    y = {n: res[n] for n in ("jib.angle", "payload.position.z", "hoist.tension_end", "payload.position.y")}
    # the jib follows its prescribed S-curve (0.6 rad, 0.1 rad/s, 0.05 rad/s^2, jerk 0.05, from 1 s): 0.0583 rad
    slew, _, _ = scurve(0.6, 0.1, 0.05, 0.05, t_start=1.0)(res.time)
    assert np.max(np.abs(y["jib.angle"] - slew)) < 1e-14                # measured 4.2e-17
    # the reel hauls in 0.078 m by 3 s (S-curve of 3 m, 0.5 m/s, 0.3 m/s^2, jerk 0.5, from 2 s); the payload
    # rises by about that, the axial mode excited by the start ringing on top: measured +14.5 %
    hauled = -scurve(-3.0, 0.5, 0.3, 0.5, t_start=2.0)(res.time)[0][-1]
    assert abs((y["payload.position.z"][-1] - y["payload.position.z"][0]) / hauled - 1) < 0.3
    assert abs(y["payload.position.y"][-1]) > 1e-2               # the slew swings the payload: 0.097 m
