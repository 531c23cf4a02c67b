"""The compiled kernels' inputs and outputs at a State, for the Python side of the solver (statics,
the scipy methods, the Simulator's queries)."""
from __future__ import annotations

import numpy as np

from ..kernel import (IN_BRAKE_E, IN_BRAKE_Z, IN_SLIP, IN_TRAC_Z, UE_BRAKE_E, UE_BRAKE_Z, UE_CREEP, UE_MOTOR_Q,
                      UE_SLIP, UE_STRIDE, UE_TORQUE, UE_TRAC_S, UE_TRAC_TH, UE_TRAC_Z, U_TORQUE)
from ..model import Model, State
from ..system import creep_inputs, outputs, workspace


def kernel_inputs(m: Model, st: State) -> np.ndarray:
    """[motor torque, brake engagement, brake deflection, motor coordinate at step start,
    traction deflection, rope s and sheave angle of the slipping sheave at step start], then per
    creep sheave (kappa, angle, sigma) at the state."""
    K = m.K
    ue = np.zeros(UE_CREEP + UE_STRIDE * K.crp_s.shape[0])
    ue[UE_TORQUE] = st.u[U_TORQUE]
    ue[UE_BRAKE_E] = st.info[IN_BRAKE_E]
    ue[UE_BRAKE_Z] = st.info[IN_BRAKE_Z]
    ue[UE_TRAC_Z] = st.info[IN_TRAC_Z]
    ue[UE_SLIP] = st.info[IN_SLIP]
    if K.crp_s.shape[0]:
        creep_inputs(m.KJ, workspace(m.KJ, st.arrays()), st.c, st.q, st.v, st.info, ue, 0.0, False)
    return ue


def kernel_inputs_at(m: Model, st: State) -> np.ndarray:
    """kernel_inputs with the step-start slots (motor coordinate, slipping sheave's s and angle) at st."""
    ue = kernel_inputs(m, st)
    K = m.K
    if K.mot_dof >= 0:
        ue[UE_MOTOR_Q] = st.q[K.mot_dof]
    if K.trac_s >= 0:
        ue[UE_TRAC_S] = st.q[K.trac_s]
        ue[UE_TRAC_TH] = st.q[K.trac_th]
    return ue


def outputs_at(m: Model, st: State) -> np.ndarray:
    """The model's outputs (m.output_names) at st."""
    y = np.empty(len(m.output_names))
    outputs(m.KJ, st.arrays(), st.c, st.q, st.v, st.qdd, st.q_ref, st.t, kernel_inputs_at(m, st), y)
    return y
