"""The closed-form Jacobian of the static forces (core/solver/statics_jac.py) against central
differences of the assembled forces, on the 8-fall crane (torsion rope, W1 wraps at the leaving span's
strain, creep drum), the two-fall crane and jointed scenes with rotating bodies (a slewing jib on a
revolute joint carrying a rotating hook; a luffing boom on a slewing superstructure). The state is the
scene's equilibrium with the bodies turned off it, so that no term vanishes by symmetry."""
import numpy as np
import pytest

from reeve_fmu.core.model import build_model
from reeve_fmu.core.scene import load_scene
from reeve_fmu.core.solver import Simulator
from reeve_fmu.core.solver.statics_jac import static_jacobian, supported
from reeve_fmu.core.system import assemble, workspace
from tests.support import ROOT

# (largest |closed form - central differences| over the statics equations' rows / largest |entry|, the
# same over the block of the rotation-vector rows and columns), bounds ~7-9x of the measured
# 8-fall 6.9e-8, 1.0e-7; two-fall 2.9e-8, 4.3e-8; luffing-slewing 1.7e-9, 2.3e-9; slewing 5.4e-9, 2.3e-8.
# The differences' own error (steps 1e-5 and 1e-7 against 1e-6) is of that size: the reference's
# truncation and round-off.
CASES = {"crane_8fall.toml": (5e-7, 1e-6), "crane_two_fall.toml": (2e-7, 4e-7),
         "luffing_crane_slewing.toml": (1.5e-8, 2e-8), "slewing_crane.toml": (5e-8, 2e-7)}
H = 1e-6   # central-difference step x (1 + |q|)


def _setup(name):
    m = build_model(load_scene(ROOT / "scenes" / name))
    sim = Simulator(m)
    st = sim.initial_state()
    for j, nm in enumerate(m.q_names):    # off the equilibrium: turn the rotating bodies
        if nm.endswith((".rx", ".ry")):
            st.q[j] += 0.01
        elif nm.endswith((".rz", ".angle")):
            st.q[j] += 0.05
    return m, sim, st


def _forces(m, st, q, u):
    M, Q = np.empty((m.nq, m.nq)), np.empty(m.nq)
    assert assemble(m.KJ, st.arrays(), st.c, q, np.zeros(m.nq), st.t, u, M, Q) >= 0
    return Q


@pytest.mark.parametrize("name", sorted(CASES))
def test_static_jacobian_against_differences(name):
    m, sim, st = _setup(name)
    assert supported(m.K)
    u = sim.kernel_inputs(st)
    ang = st.nl_ang.copy()
    J = np.zeros((m.nq, m.nq))
    assert static_jacobian(m.KJ, workspace(m.KJ, st.arrays()), st.c, st.q.copy(), np.zeros(m.nq), u, J) >= 0
    eqs = np.array(m.statics_equations)
    Jd = np.zeros((m.nq, m.nq))
    for j in range(m.nq):      # every column (a prescribed joint's too), the statics equations' rows
        h = H * (1.0 + abs(st.q[j]))
        qp, qm = st.q.copy(), st.q.copy()
        qp[j] += h
        qm[j] -= h
        st.nl_ang[:] = ang          # the exact tangents' warm start of q for both
        Qp = _forces(m, st, qp, u)
        st.nl_ang[:] = ang
        Jd[:, j] = (Qp - _forces(m, st, qm, u)) / (2.0 * h)
    A, B = J[eqs], Jd[eqs]
    err = np.max(np.abs(A - B)) / np.max(np.abs(B))
    # the rotations' block on its own scale (the yaw stiffness that decides cabling is ~1e-4 of EA / l)
    rot = [j for j, nm in enumerate(m.q_names) if nm.endswith((".rx", ".ry", ".rz"))]
    Ar, Br = J[np.ix_(rot, rot)], Jd[np.ix_(rot, rot)]
    err_rot = np.max(np.abs(Ar - Br)) / np.max(np.abs(Br))
    print(f"{name}: {err:.3g} of the largest entry {np.max(np.abs(B)):.4g}; rotations {err_rot:.3g} of "
          f"{np.max(np.abs(Br)):.4g}")
    assert err < CASES[name][0]
    assert err_rot < CASES[name][1]
