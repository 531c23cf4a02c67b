"""Linearisation of a model at rest for the mode tests: (M, K) on the free coordinates, K = -dQ/dq."""
import numpy as np

from reeve_fmu.core.system import assemble


def linearised(sim, st, dq=1e-5):
    """(M, K) on the free coordinates at the state st: K = -dQ/dq by central differences of step dq.
    The kernel's maps are left at st (the last assembly is at st)."""
    m = sim.model
    f = m.K.free
    M, Q = np.empty((m.nq, m.nq)), np.empty(m.nq)
    u = sim.kernel_inputs(st)
    assemble(m.KJ, st.arrays(), st.c, st.q, st.v, st.t, u, M, Q)
    Mf = M[np.ix_(f, f)].copy()
    Kf = np.empty((len(f), len(f)))
    for k, j in enumerate(f):
        cols = []
        for sgn in (1.0, -1.0):
            q = st.q.copy()
            q[j] += sgn * dq
            assemble(m.KJ, st.arrays(), st.c, q, st.v, st.t, u, M, Q)
            cols.append(Q[f].copy())
        Kf[:, k] = -(cols[0] - cols[1]) / (2 * dq)
    assemble(m.KJ, st.arrays(), st.c, st.q, st.v, st.t, u, M, Q)
    return Mf, Kf
