"""The compiled kernels' inputs and outputs at a State, for the Python side of the solver (statics,
the scipy methods, the Simulator's queries)."""
from __future__ import annotations

import numpy as np

from ..model import Model, State
from ..contact import UE_CREEP, UE_STRIDE
from ..system import creep_inputs, outputs


def kernel_inputs(m: Model, st: State) -> np.ndarray:
    """[motor torque, brake engagement, brake deflection, motor coordinate at step start,
    traction deflection, rope s and sheave angle of the slipping sheave at step start], then per
    creep sheave (kappa, angle, sigma) at the state."""
    K = m.K
    ue = np.zeros(UE_CREEP + UE_STRIDE * K.crp_s.shape[0])
    ue[:UE_CREEP] = (st.u[0], st.info[5], st.info[6], 0.0, st.info[8], 0.0, 0.0, st.info[9])
    if K.crp_s.shape[0]:
        creep_inputs(m.KJ, st.c, st.q, st.v, st.info, ue, 0.0, *element_buffers(m), False)
    return ue


def element_buffers(m: Model):
    n_el, ne = m.K.el_idx.shape
    return np.empty((n_el, ne)), np.empty((n_el, ne))


def kernel_inputs_at(m: Model, st: State) -> np.ndarray:
    """kernel_inputs with the step-start slots (motor coordinate, slipping sheave's s and angle) at st."""
    ue = kernel_inputs(m, st)
    K = m.K
    if K.mot_dof >= 0:
        ue[3] = st.q[K.mot_dof]
    if K.trac_s >= 0:
        ue[5] = st.q[K.trac_s]
        ue[6] = st.q[K.trac_th]
    return ue


def outputs_at(m: Model, st: State) -> np.ndarray:
    """The model's outputs (m.output_names) at st."""
    y = np.empty(len(m.output_names))
    outputs(m.KJ, st.c, st.q, st.v, st.qdd, st.q_ref, st.t, kernel_inputs_at(m, st), y)
    return y
