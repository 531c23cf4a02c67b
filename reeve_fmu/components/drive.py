"""Electric drive of a traction machine: trip sequencer, speed/position control, torque path, brake command.

`ElectricDrive` is a sampled-data controller with its own fixed clock (speed loop every `Ts`, Level-2
current loop every `Ts_current`); `step(t, dt, motor_speed, motor_angle)` runs every controller tick that
falls in [t, t + dt) on the measurement held from t (angle extrapolated with the speed), and integrates the
torque path exactly (Level 1) or with RK4 (Level 2) between ticks. Any dt > 0 is accepted and the result
is deterministic; a finer communication step only refreshes the measurement more often.

Sign convention: positive motor speed, angle and torque move the car UP. Car positions (landings) are
in metres, increasing upward. The measured car position is inferred from the motor angle,
x = x_landing + (theta - theta_at_move_start) * R / roping, so the drive controls the sheave, not the car
(rope stretch is the plant's business). Optionally (`sis = True`) a shaft information system gives the
absolute car position (quantized to `sis_resolution`, `sis_delay` old); the offset between it and the
encoder's car position (the rope stretch) is low-passed (`sis_filter`) and blended into the position
loop over the last `sis_zone` metres of each approach, so the car, not the sheave, is levelled.

Brake command: 1.0 = release (open) the brake, 0.0 = apply (close) it.

The drive is pure Python + numpy; the per-step kernel is compiled with numba when available (`_jit`).
All hidden state lives in two flat arrays exported by `get_state()` as builtin lists, so FMI
get/set/serialize FMU state rewinds it bit-identically.

`DRIVE_PARAMETERS` are the drive FMU's parameters (defaults: reference set R1 with the pre-torque
`R1_PRETORQUE`); `make_drive(values)` builds the ElectricDrive for their values (the FMU, the
monolithic reference and the HIL controller call it).
"""
from __future__ import annotations

from dataclasses import dataclass
import math
import numbers
from typing import Mapping, Optional, Sequence

import numpy as np

from ..core._jit import entry_point, njit
from ..core.profiles import Profile, profile_eval, scurve_phases, trip_sequence

# ---------------------------------------------------------------------------------------------------
# Phases of the trip state machine (ints so the compiled kernel can use them)
PHASE_IDLE = 0        # before the first move: torque off, brake applied
PHASE_PRETORQUE = 1   # brake applied, torque ramps to the load-weighing pre-torque
PHASE_LIFT = 2        # brake release commanded, position hold at zero speed (anti-rollback)
PHASE_RUN = 3         # S-curve running
PHASE_HOLD = 4        # profile finished, zero-speed position hold, brake still open
PHASE_DROP = 5        # brake apply commanded, the holding torque is held until the brake has engaged
PHASE_RAMPDOWN = 6    # brake engaged, torque ramps linearly to zero
PHASE_DWELL = 7       # at rest between moves: torque off, brake applied
PHASE_DONE = 8        # after the last move
PHASE_NAMES = ("idle", "pretorque", "lift", "run", "hold", "drop", "rampdown", "dwell", "done")
_RELEASED = (PHASE_LIFT, PHASE_RUN, PHASE_HOLD)   # phases with the brake commanded open

# schedule columns (one row per move)
_S_TP, _S_TL, _S_TR, _S_TS, _S_TD, _S_TZ, _S_TO, _S_X0, _S_PRE, _S_X1 = range(10)
_NS = 10

# parameter vector layout for the kernel
(_P_HB, _P_NSP, _P_LEVEL, _P_R, _P_ROP, _P_JFF, _P_TMAX, _P_PMAX, _P_TAU, _P_ND, _P_KP, _P_KI,
 _P_KPOS, _P_TPRE, _P_TRAMP, _P_NPP, _P_PSI, _P_RS, _P_LD, _P_LQ, _P_VMAX, _P_KPD, _P_KID, _P_KPQ,
 _P_KIQ, _P_SIS, _P_SISTAU) = range(27)
_NP = 27

# float state layout (integer state: _I_*); the dead-time buffer follows _X_BUF0
(_X_TM, _X_TT, _X_INT, _X_TH0, _X_TREF, _X_TR0, _X_TIME, _X_TMEAN, _X_WCMD, _X_EPOS, _X_XREF,
 _X_VREF, _X_AREF, _X_ID, _X_IQ, _X_VDA, _X_VQA, _X_VDN, _X_VQN, _X_ITD, _X_ITQ, _X_IQREF, _X_SOFF,
 _X_SINIT) = range(24)
_X_BUF0 = 24
_I_K, _I_MOVE, _I_PHASE, _I_HEAD = range(4)
_NI = 4

_STATE_FORMAT = "reeve_fmu.drive/1"


@dataclass
class DriveParams:
    """Drive parameters, SI units. Defaults: reference set R1 of docs/reference-sets.md §1 (1000 kg, 1.6 m/s, 2:1 MRL).

    Sequence per move: pre-torque ramp (`pretorque_time`) -> brake release command -> wait
    `brake_lift_delay` -> S-curve to the target landing -> zero-speed hold (`hold_time`) -> brake apply
    command -> wait `brake_drop_delay` holding the last torque (speed loop open while the brake closes) ->
    torque ramp to zero (`torque_ramp_time`) -> `dwell_time` -> next move. The first move starts its
    pre-torque at `start_delay`.
    """

    # mechanics as seen by the drive
    sheave_radius: float = 0.16        # m
    roping: float = 2.0                # rope speed / car speed
    J_ff: float = 28.0                 # kg m², inertia at the motor shaft for the feed-forward J*alpha_ref
    # limits
    T_max: float = 1000.0              # N m
    P_max: float = 20e3                # W, |T * omega| limit (motoring and regenerating)
    # Level 1 torque path (closed current loop seen from outside)
    tau_T: float = 0.5e-3              # s, first-order torque lag
    dead_time: float = 0.25e-3         # s, rounded to whole `Ts` sub-steps
    # speed / position control
    Ts: float = 125e-6                 # s, speed-loop sample time and Level-1 internal sub-step
    Kp: float = 970.0                  # N m s/rad, symmetric optimum at ~5 Hz (docs/reference-sets.md §3.1)
    Ti: float = 0.127                  # s, speed PI integral time (math.inf disables the integrator)
    Kpos: float = 2.0                  # 1/s, position P gain added to the speed reference
    # S-curve and trip sequence
    v_max: float = 1.6                 # m/s car
    a_max: float = 0.8                 # m/s² car
    jerk: float = 1.0                  # m/s³ car
    landings: Sequence[float] = (0.0, 39.0)   # m, car position at each landing
    start_landing: int = 0             # index into landings where the car starts
    moves: Sequence[int] = (1, 0)      # target landing index of each move, run in order
    start_delay: float = 0.5           # s before the first pre-torque
    pretorque_time: float = 0.2        # s, torque ramp 0 -> pre-torque with the brake applied
    brake_lift_delay: float = 0.2      # s waited after the release command before the profile starts
    hold_time: float = 0.3             # s zero-speed hold after the profile before the apply command
    brake_drop_delay: float = 0.2      # s waited after the apply command before torque ramps down
    torque_ramp_time: float = 0.2      # s, holding torque -> 0 with the brake applied
    dwell_time: float = 3.0            # s at rest between moves
    # load-weighing pre-torque (N m): one value for every start, or one per landing (car starting there)
    pretorque: float | Sequence[float] = 0.0
    # carried for the brake model / FMU wrapper; the controller itself does not use it
    brake_static_torque: Sequence[float] = (700.0, 700.0)   # N m per circuit
    # model level: 1 = torque lag + dead time, 2 = PMSM dq model with current PI
    level: int = 1
    # Level 2 machine (R1 PMSM) and inverter
    pole_pairs: int = 12
    psi: float = 0.90                  # Wb, PM flux linkage (amplitude-invariant dq)
    Rs: float = 0.7                    # ohm
    Ld: float = 12e-3                  # H
    Lq: float = 12e-3                  # H
    V_dc: float = 565.0                # V, DC link; voltage limit |v_dq| <= V_dc/sqrt(3) (SVPWM)
    Ts_current: float = 62.5e-6        # s, current-loop sample time (must divide Ts)
    Kp_current: float | None = None    # V/A; None = technical optimum L/(2*1.5*Ts_current) per axis
    Ti_current: float | None = None    # s;   None = L/Rs per axis
    # shaft information system (absolute car position) for the approach; needs car_position in step()
    sis: bool = False
    sis_resolution: float = 0.5e-3     # m, position quantum
    sis_delay: float = 2e-3            # s, measurement age
    sis_zone: float = 0.0              # m before the target over which the loop blends encoder -> SIS;
                                       # 0: the braking distance v_max²/(2 a_max), at least 0.3 m
    sis_filter: float = 0.2            # s, time constant of the low-pass on the SIS - encoder offset

    def validate(self) -> None:
        """Raise ValueError naming the first bad parameter."""
        def pos(name, allow_inf=False):
            v = getattr(self, name)
            if not isinstance(v, numbers.Real) or isinstance(v, bool) or math.isnan(v) or v <= 0 \
                    or (math.isinf(v) and not allow_inf):
                raise ValueError(f"DriveParams.{name} must be a positive number, got {v!r}")

        def nonneg(name, allow_inf=False):
            v = getattr(self, name)
            if not isinstance(v, numbers.Real) or isinstance(v, bool) or math.isnan(v) or v < 0 \
                    or (math.isinf(v) and not allow_inf):
                raise ValueError(f"DriveParams.{name} must be a number >= 0, got {v!r}")

        for n in ("sheave_radius", "roping", "T_max", "Ts", "v_max", "a_max", "jerk"):
            pos(n)
        pos("P_max", allow_inf=True)
        pos("Ti", allow_inf=True)
        for n in ("J_ff", "tau_T", "dead_time", "Kp", "Kpos", "start_delay", "pretorque_time",
                  "brake_lift_delay", "hold_time", "brake_drop_delay", "torque_ramp_time", "dwell_time"):
            nonneg(n)
        if self.sis:
            for n in ("sis_resolution", "sis_filter"):
                pos(n)
            nonneg("sis_zone")
            nonneg("sis_delay")
        if self.level not in (1, 2):
            raise ValueError(f"DriveParams.level must be 1 or 2, got {self.level!r}")
        lands = list(self.landings)
        if len(lands) < 1 or not all(isinstance(x, numbers.Real) and math.isfinite(x) for x in lands):
            raise ValueError(f"DriveParams.landings must be a non-empty list of finite positions, got {self.landings!r}")
        if not (isinstance(self.start_landing, numbers.Integral) and 0 <= self.start_landing < len(lands)):
            raise ValueError(f"DriveParams.start_landing must be an index into landings (0..{len(lands) - 1}), "
                             f"got {self.start_landing!r}")
        for m in self.moves:
            if not (isinstance(m, numbers.Integral) and 0 <= m < len(lands)):
                raise ValueError(f"DriveParams.moves must hold landing indices 0..{len(lands) - 1}, got {m!r}")
        if isinstance(self.pretorque, numbers.Real):
            if not math.isfinite(self.pretorque):
                raise ValueError(f"DriveParams.pretorque must be finite, got {self.pretorque!r}")
        else:
            pre = list(self.pretorque)
            if len(pre) != len(lands) or not all(math.isfinite(float(p)) for p in pre):
                raise ValueError("DriveParams.pretorque must be a number or one finite value per landing "
                                 f"({len(lands)}), got {self.pretorque!r}")
        if any(abs(p) > self.T_max for p in self._pretorques()):
            raise ValueError(f"DriveParams.pretorque exceeds T_max = {self.T_max} N m")
        if self.level == 2:
            if not (isinstance(self.pole_pairs, numbers.Integral) and self.pole_pairs > 0):
                raise ValueError(f"DriveParams.pole_pairs must be a positive integer, got {self.pole_pairs!r}")
            for n in ("psi", "Rs", "Ld", "Lq", "V_dc", "Ts_current"):
                pos(n)
            ratio = self.Ts / self.Ts_current
            if abs(ratio - round(ratio)) > 1e-9 * ratio or round(ratio) < 1:
                raise ValueError(f"DriveParams.Ts_current must divide Ts ({self.Ts} s), got {self.Ts_current}")
            if self.Kp_current is not None:
                pos("Kp_current")
            if self.Ti_current is not None:
                pos("Ti_current", allow_inf=True)

    def _pretorques(self) -> list[float]:
        if isinstance(self.pretorque, numbers.Real):
            return [float(self.pretorque)] * len(list(self.landings))
        return [float(p) for p in self.pretorque]


# ---------------------------------------------------------------------------------------------------
# compiled kernel

@njit(cache=True)
def _phase_at(sched, t):
    """(phase, move index) of the trip schedule at time t."""
    n = sched.shape[0]
    for i in range(n):
        if t < sched[i, _S_TP]:
            if i == 0:
                return PHASE_IDLE, -1
            return PHASE_DWELL, i - 1
        if t < sched[i, _S_TL]:
            return PHASE_PRETORQUE, i
        if t < sched[i, _S_TR]:
            return PHASE_LIFT, i
        if t < sched[i, _S_TS]:
            return PHASE_RUN, i
        if t < sched[i, _S_TD]:
            return PHASE_HOLD, i
        if t < sched[i, _S_TZ]:
            return PHASE_DROP, i
        if t < sched[i, _S_TO]:
            return PHASE_RAMPDOWN, i
    if n == 0:
        return PHASE_DONE, -1
    return PHASE_DONE, n - 1


@njit(cache=True)
def _torque_l2(P, i_d, i_q):
    return 1.5 * P[_P_NPP] * (P[_P_PSI] * i_q + (P[_P_LD] - P[_P_LQ]) * i_d * i_q)


@njit(cache=True)
def _didt(P, i_d, i_q, vd, vq, we):
    did = (vd - P[_P_RS] * i_d + we * P[_P_LQ] * i_q) / P[_P_LD]
    diq = (vq - P[_P_RS] * i_q - we * (P[_P_LD] * i_d + P[_P_PSI])) / P[_P_LQ]
    return did, diq


@njit(cache=True)
def _propagate(xs, P, tau, w):
    """Advance the torque path by tau at constant measured speed w; return the torque integral."""
    if tau <= 0.0:
        return 0.0
    if int(P[_P_LEVEL]) == 1:
        T0 = xs[_X_TM]
        Tt = xs[_X_TT]
        if P[_P_TAU] > 0.0:
            e = math.exp(-tau / P[_P_TAU])
            xs[_X_TM] = Tt + (T0 - Tt) * e
            # exact integral of the first-order response under a held target
            return Tt * tau + (T0 - Tt) * P[_P_TAU] * (1.0 - e)
        xs[_X_TM] = Tt
        return Tt * tau
    # Level 2: PMSM dq currents under the held inverter voltage, one RK4 step (|lambda|*tau << 1)
    we = P[_P_NPP] * w
    vd = xs[_X_VDA]
    vq = xs[_X_VQA]
    i_d = xs[_X_ID]
    i_q = xs[_X_IQ]
    T0 = _torque_l2(P, i_d, i_q)
    k1d, k1q = _didt(P, i_d, i_q, vd, vq, we)
    k2d, k2q = _didt(P, i_d + 0.5 * tau * k1d, i_q + 0.5 * tau * k1q, vd, vq, we)
    k3d, k3q = _didt(P, i_d + 0.5 * tau * k2d, i_q + 0.5 * tau * k2q, vd, vq, we)
    k4d, k4q = _didt(P, i_d + tau * k3d, i_q + tau * k3q, vd, vq, we)
    i_d = i_d + tau / 6.0 * (k1d + 2.0 * k2d + 2.0 * k3d + k4d)
    i_q = i_q + tau / 6.0 * (k1q + 2.0 * k2q + 2.0 * k3q + k4q)
    xs[_X_ID] = i_d
    xs[_X_IQ] = i_q
    T1 = _torque_l2(P, i_d, i_q)
    xs[_X_TM] = T1
    return 0.5 * (T0 + T1) * tau


@njit(cache=True)
def _speed_tick(xs, xi, P, sched, prof, tk, w, th, xsis):
    """Sequencer + position/speed control at a speed-loop tick; sets xs[_X_TREF]. `xsis`: car position
    of the shaft information system (NaN: none)."""
    phase, move = _phase_at(sched, tk)
    prev_phase = xi[_I_PHASE]
    if move != xi[_I_MOVE]:
        # a new move begins: reference the measured angle, clear the integrator
        xi[_I_MOVE] = move
        xs[_X_TH0] = th
        xs[_X_INT] = 0.0
        xs[_X_SINIT] = 0.0
        prev_phase = PHASE_IDLE
    x_ref, v_ref, a_ref = profile_eval(prof, tk)
    xs[_X_XREF] = x_ref
    xs[_X_VREF] = v_ref
    xs[_X_AREF] = a_ref
    g = P[_P_ROP] / P[_P_R]          # motor rad per metre of car travel
    Tref = 0.0
    if phase == PHASE_LIFT or phase == PHASE_RUN or phase == PHASE_HOLD or phase == PHASE_DROP:
        th_ref = xs[_X_TH0] + (x_ref - sched[move, _S_X0]) * g
        epos = th_ref - th
        if P[_P_SIS] > 0.0 and xsis == xsis:
            # car position = encoder position + rope stretch offset; the offset (SIS - encoder) is
            # low-passed with sis_filter so that the loop stays collocated on the sheave: feeding the
            # car position back directly excites the rope's bounce mode (measured: a sustained
            # +-25 mm, 1.3 Hz oscillation at the bottom of the 200 m high-rise)
            raw = xsis - (sched[move, _S_X0] + (th - xs[_X_TH0]) / g)
            if xs[_X_SINIT] == 0.0:
                xs[_X_SOFF] = raw
                xs[_X_SINIT] = 1.0
            else:
                f = P[_P_HB] * P[_P_NSP] / P[_P_SISTAU]
                xs[_X_SOFF] += (raw - xs[_X_SOFF]) * (f if f < 1.0 else 1.0)
            # applied over the last sis_zone metres of the approach (a smooth blend)
            wgt = 1.0 - abs(sched[move, _S_X1] - x_ref) / P[_P_SIS]
            if wgt > 0.0:
                if wgt > 1.0:
                    wgt = 1.0
                epos -= wgt * g * xs[_X_SOFF]
        wcmd = g * v_ref + P[_P_KPOS] * epos
        e = wcmd - w
        Tpre = sched[move, _S_PRE]
        Tu = P[_P_KP] * e + xs[_X_INT] + P[_P_JFF] * g * a_ref + Tpre
        aw = abs(w)
        Tlim = P[_P_TMAX]
        if aw * Tlim > P[_P_PMAX]:
            Tlim = P[_P_PMAX] / aw
        Tref = Tu
        if Tref > Tlim:
            Tref = Tlim
        elif Tref < -Tlim:
            Tref = -Tlim
        if phase == PHASE_DROP:
            # brake closing: hold the torque that held the car at zero speed, speed loop open. Closed on
            # the engaging brake (a ~380 Hz stick spring on the rotor) the loop, fed once per
            # communication step, chatters step to step (1 ms Jacobi / 2 ms Gauss-Seidel)
            if prev_phase != PHASE_DROP:
                xs[_X_TR0] = xs[_X_TREF]
            Tref = xs[_X_TR0]
        elif not ((Tu > Tlim and e > 0.0) or (Tu < -Tlim and e < 0.0)):
            # anti-windup: conditional integration, frozen while saturated in the direction of the error
            xs[_X_INT] += P[_P_KI] * e * (P[_P_HB] * P[_P_NSP])
        xs[_X_WCMD] = wcmd
        xs[_X_EPOS] = epos
    else:
        xs[_X_WCMD] = 0.0
        if phase == PHASE_PRETORQUE:
            Tpre = sched[move, _S_PRE]
            if P[_P_TPRE] > 0.0:
                f = (tk - sched[move, _S_TP]) / P[_P_TPRE]
                Tref = Tpre * min(max(f, 0.0), 1.0)
            else:
                Tref = Tpre
        elif phase == PHASE_RAMPDOWN:
            if prev_phase != PHASE_RAMPDOWN:
                xs[_X_TR0] = xs[_X_TREF]
            if P[_P_TRAMP] > 0.0:
                f = (tk - sched[move, _S_TZ]) / P[_P_TRAMP]
                Tref = xs[_X_TR0] * (1.0 - min(max(f, 0.0), 1.0))
        else:
            xs[_X_INT] = 0.0
    xs[_X_TREF] = Tref
    xi[_I_PHASE] = phase


@njit(cache=True)
def _current_tick(xs, P, w):
    """Level-2 dq current PI (i_d = 0) with decoupling, voltage limit and one-sample computation delay."""
    h = P[_P_HB]
    i_d = xs[_X_ID]
    i_q = xs[_X_IQ]
    we = P[_P_NPP] * w
    ed = 0.0 - i_d
    eq = xs[_X_IQREF] - i_q
    vd = P[_P_KPD] * ed + xs[_X_ITD] - we * P[_P_LQ] * i_q
    vq = P[_P_KPQ] * eq + xs[_X_ITQ] + we * (P[_P_LD] * i_d + P[_P_PSI])
    vm = math.sqrt(vd * vd + vq * vq)
    if vm > P[_P_VMAX]:
        s = P[_P_VMAX] / vm
        vd *= s
        vq *= s
    else:
        # integrate only when the voltage is not limited (anti-windup)
        xs[_X_ITD] += P[_P_KID] * ed * h
        xs[_X_ITQ] += P[_P_KIQ] * eq * h
    # the voltage computed now is applied during the next sample (computation delay)
    xs[_X_VDA] = xs[_X_VDN]
    xs[_X_VQA] = xs[_X_VQN]
    xs[_X_VDN] = vd
    xs[_X_VQN] = vq


@njit(cache=True)
def _advance(xs, xi, P, sched, prof, t0, t1, w, th, xsis):
    """Run every controller tick in [t0, t1) and the torque path up to t1; returns the torque at t1."""
    hb = P[_P_HB]
    nsp = int(P[_P_NSP])
    level = int(P[_P_LEVEL])
    nd = int(P[_P_ND])
    eps = 1e-6 * hb
    tc = t0
    tsum = 0.0
    while True:
        k = xi[_I_K]
        tk = k * hb
        if tk >= t1 - eps:
            break
        if tk > tc:
            tsum += _propagate(xs, P, tk - tc, w)
            tc = tk
        thk = th + w * (tk - t0)     # angle extrapolated with the held speed
        if k % nsp == 0:
            _speed_tick(xs, xi, P, sched, prof, tk, w, thk, xsis)
            if level == 2:
                xs[_X_IQREF] = xs[_X_TREF] / (1.5 * P[_P_NPP] * P[_P_PSI])
        if level == 2:
            _current_tick(xs, P, w)
        else:
            # dead time: the reference computed now reaches the torque lag nd ticks later
            Tin = xs[_X_TREF]
            if nd == 0:
                xs[_X_TT] = Tin
            else:
                hd = xi[_I_HEAD]
                xs[_X_TT] = xs[_X_BUF0 + hd]
                xs[_X_BUF0 + hd] = Tin
                xi[_I_HEAD] = (hd + 1) % nd
        xi[_I_K] = k + 1
    if t1 > tc:
        tsum += _propagate(xs, P, t1 - tc, w)
    xs[_X_TMEAN] = tsum / (t1 - t0) if t1 > t0 else xs[_X_TM]
    xs[_X_TIME] = t1
    return xs[_X_TM]


# ---------------------------------------------------------------------------------------------------

class ElectricDrive:
    """Electric drive (controller + torque path) for co-simulation with a plant that integrates J_m.

    Use: ``d = ElectricDrive(DriveParams()); tau, brake = d.step(t, dt, omega_motor, theta_motor)``
    for t = 0, dt, 2dt, ...; `tau` (N m, air-gap torque at t + dt, positive lifts the car) and `brake`
    (1.0 release/open, 0.0 apply/close) are the values to hold over the next step. `torque_mean` is the
    exact mean torque over the step just taken (Level 1).
    """

    def __init__(self, params: DriveParams | None = None):
        self.params = params if params is not None else DriveParams()
        p = self.params
        p.validate()
        self._build_schedule()
        nd = int(round(p.dead_time / p.Ts)) if p.level == 1 else 0
        self._nd = nd
        if p.level == 2:
            hb = p.Ts_current
            nsp = int(round(p.Ts / p.Ts_current))
            tsig = 1.5 * p.Ts_current            # technical optimum: T_sigma = 1.5 sample times
            kpd = p.Kp_current if p.Kp_current is not None else p.Ld / (2.0 * tsig)
            kpq = p.Kp_current if p.Kp_current is not None else p.Lq / (2.0 * tsig)
            tid = p.Ti_current if p.Ti_current is not None else p.Ld / p.Rs
            tiq = p.Ti_current if p.Ti_current is not None else p.Lq / p.Rs
            kid, kiq = kpd / tid, kpq / tiq
        else:
            hb, nsp = p.Ts, 1
            kpd = kpq = kid = kiq = 0.0
        P = np.zeros(_NP)
        P[_P_HB], P[_P_NSP], P[_P_LEVEL] = hb, nsp, p.level
        P[_P_R], P[_P_ROP], P[_P_JFF] = p.sheave_radius, p.roping, p.J_ff
        P[_P_TMAX], P[_P_PMAX], P[_P_TAU], P[_P_ND] = p.T_max, p.P_max, p.tau_T, nd
        P[_P_KP], P[_P_KI], P[_P_KPOS] = p.Kp, (p.Kp / p.Ti if math.isfinite(p.Ti) else 0.0), p.Kpos
        P[_P_TPRE], P[_P_TRAMP] = p.pretorque_time, p.torque_ramp_time
        P[_P_NPP], P[_P_PSI], P[_P_RS], P[_P_LD], P[_P_LQ] = p.pole_pairs, p.psi, p.Rs, p.Ld, p.Lq
        P[_P_VMAX] = p.V_dc / math.sqrt(3.0)
        P[_P_KPD], P[_P_KID], P[_P_KPQ], P[_P_KIQ] = kpd, kid, kpq, kiq
        zone = p.sis_zone if p.sis_zone > 0 else max(0.3, p.v_max ** 2 / (2.0 * p.a_max))
        P[_P_SIS] = zone if p.sis else 0.0
        P[_P_SISTAU] = p.sis_filter
        self._P = P
        self._sis_hist: list = []          # (t, car position) samples not yet older than sis_delay
        self._xs = np.zeros(_X_BUF0 + max(nd, 1))
        self._xi = np.zeros(_NI, dtype=np.int64)
        self._advance = _advance           # its entry point after the first call (step)
        self.reset()

    # -- setup ---------------------------------------------------------------------------------------
    def _build_schedule(self):
        p = self.params
        lands = [float(x) for x in p.landings]
        pre = p._pretorques()
        rows, moves = [], []
        t = p.start_delay
        cur = p.start_landing
        for tgt in p.moves:
            dist = lands[tgt] - lands[cur]
            dur = sum(scurve_phases(dist, p.v_max, p.a_max, p.jerk)[0])
            tp = t
            tl = tp + p.pretorque_time
            tr = tl + p.brake_lift_delay
            ts = tr + dur
            td = ts + p.hold_time
            tz = td + p.brake_drop_delay
            to = tz + p.torque_ramp_time
            rows.append([tp, tl, tr, ts, td, tz, to, 0.0, pre[cur], lands[tgt]])
            moves.append((tr, dist))
            t = to + p.dwell_time
            cur = tgt
        self.profile: Profile = trip_sequence(moves, p.v_max, p.a_max, p.jerk, x_start=lands[p.start_landing])
        self._prof = np.ascontiguousarray(self.profile.arrays)
        sched = np.array(rows, dtype=float).reshape(len(rows), _NS)
        for i in range(len(rows)):
            # reference position at the profile start of move i (exactly what profile_eval returns)
            sched[i, _S_X0] = profile_eval(self._prof, sched[i, _S_TR])[0]
        self._sched = np.ascontiguousarray(sched)

    def reset(self, t0: float = 0.0) -> None:
        """Back to the initial state at time t0 (car at the start landing, brake applied, torque 0)."""
        if not math.isfinite(t0):
            raise ValueError(f"reset: t0 must be finite, got {t0!r}")
        self._xs[:] = 0.0
        self._xi[:] = 0
        hb = self._P[_P_HB]
        self._xi[_I_K] = int(math.ceil(t0 / hb - 1e-6))
        self._xi[_I_MOVE] = -1
        self._xi[_I_PHASE] = PHASE_IDLE
        self._xs[_X_TIME] = t0
        x, v, a = profile_eval(self._prof, t0)
        self._xs[_X_XREF], self._xs[_X_VREF], self._xs[_X_AREF] = x, v, a
        self._sis_hist = []

    def _sis_reading(self, t: float, car_position: float) -> float:
        """SIS position at t: the newest sample at least sis_delay old, quantized; NaN before one exists."""
        p = self.params
        if not p.sis or not math.isfinite(car_position):
            return math.nan
        h = self._sis_hist
        h.append((t, float(car_position)))
        cutoff = t - p.sis_delay + 1e-12
        while len(h) > 1 and h[1][0] <= cutoff:     # keep the newest sample that is old enough
            h.pop(0)
        if h[0][0] > cutoff:
            return math.nan
        x = h[0][1]
        return round(x / p.sis_resolution) * p.sis_resolution

    # -- stepping -------------------------------------------------------------------------------------
    def step(self, t: float, dt: float, motor_speed: float, motor_angle: float,
             car_position: float = math.nan) -> tuple[float, float]:
        """Advance from t to t + dt with the measured motor speed (rad/s) and angle (rad) held from t;
        `car_position` (m) feeds the shaft information system when params.sis (sampled every step).

        Returns (torque N m at t + dt, brake_command: 1.0 release / 0.0 apply). t must continue from the
        drive's time (previous t + dt, reset or set_state time) within 1 µs."""
        if not (dt > 0.0 and math.isfinite(dt)):
            raise ValueError(f"step: dt must be a finite number > 0, got {dt!r}")
        if not (math.isfinite(motor_speed) and math.isfinite(motor_angle)):
            raise ValueError(f"step: motor_speed and motor_angle must be finite, got {motor_speed!r}, {motor_angle!r}")
        xs, xi = self._xs, self._xi
        t_int = xs.item(_X_TIME)
        if not abs(t - t_int) <= 1e-6:
            raise ValueError(f"step: t = {t!r} s does not continue from the drive time {t_int!r} s "
                             "(use reset(t0) or set_state to move the drive in time)")
        xsis = self._sis_reading(float(t), car_position) if self.params.sis else math.nan
        tau = self._advance(xs, xi, self._P, self._sched, self._prof, t_int, float(t) + float(dt),
                            float(motor_speed), float(motor_angle), xsis)
        if self._advance is _advance:      # compiled now: call it without numba's argument typing
            self._advance = entry_point(_advance)
        return float(tau), (1.0 if xi.item(_I_PHASE) in _RELEASED else 0.0)

    def warm_up(self) -> None:
        """Load (or compile) the step kernel now with a throw-away step on copies of the state, so that
        an FMU's first doStep costs what every other one costs (a cold numba cache takes seconds)."""
        t = float(self._xs[_X_TIME])
        _advance(self._xs.copy(), self._xi.copy(), self._P, self._sched, self._prof, t, t + 1e-3, 0.0, 0.0,
                 math.nan)

    def next_command_switch(self, t0: float, t1: float) -> Optional[float]:
        """The first speed-loop tick in (t0, t1) at which the brake command changes (the release
        command at the pre-torque's end, the apply command after the zero-speed hold), else None. A
        step from t0 to that tick still gives the old command; the tick runs at the start of the next
        step (ticks run in [t, t + dt)), whose command is then the new one from the tick on."""
        hb, nsp = float(self._P[_P_HB]), int(self._P[_P_NSP])
        eps = 1e-6 * hb                           # _advance's tick tolerance
        for row in self._sched:
            for ti in (row[_S_TL], row[_S_TD]):
                m = math.ceil(ti / (nsp * hb) - 1e-9)
                if (m * nsp) * hb < ti:
                    m += 1
                tick = (m * nsp) * hb             # the first speed tick at or after the switch (_advance's k hb)
                if t0 + eps < tick < t1 - eps:
                    return float(tick)
                if tick >= t1:
                    return None
        return None

    # -- FMU state ------------------------------------------------------------------------------------
    def get_state(self) -> dict:
        """All hidden state as builtin Python types (JSON/pickle-safe)."""
        return {"format": _STATE_FORMAT, "level": int(self.params.level),
                "xs": [float(v) for v in self._xs], "xi": [int(v) for v in self._xi],
                "sis": [list(v) for v in self._sis_hist]}

    def set_state(self, state: dict) -> None:
        """Restore a state from get_state() of a drive with the same parameters."""
        try:
            fmt, level, xs, xi = state["format"], state["level"], state["xs"], state["xi"]
        except (KeyError, TypeError) as exc:
            raise ValueError(f"set_state: not a drive state dict ({exc})") from None
        if fmt != _STATE_FORMAT or level != self.params.level or len(xs) != self._xs.size \
                or len(xi) != self._xi.size:
            raise ValueError("set_state: state does not match this drive (format, level or dead-time buffer size)")
        self._xs[:] = np.asarray(xs, dtype=float)
        self._xi[:] = np.asarray(xi, dtype=np.int64)
        self._sis_hist = [tuple(v) for v in state.get("sis", [])]

    # -- outputs ---------------------------------------------------------------------------------------
    @property
    def time(self) -> float:
        """Drive time, s (end of the last step)."""
        return float(self._xs[_X_TIME])

    @property
    def t_end(self) -> float:
        """Time at which the whole move sequence is finished (torque off after the last move), s."""
        return float(self._sched[-1, _S_TO]) if len(self._sched) else float(self.params.start_delay)

    @property
    def phase(self) -> int:
        """Sequencer phase at the last controller tick (PHASE_* constants)."""
        return int(self._xi[_I_PHASE])

    @property
    def phase_name(self) -> str:
        return PHASE_NAMES[self.phase]

    @property
    def move_index(self) -> int:
        """Index into params.moves of the current/last move, -1 before the first."""
        return int(self._xi[_I_MOVE])

    @property
    def brake_command(self) -> float:
        """1.0 = release (open) the brake, 0.0 = apply (close) it."""
        return 1.0 if self.phase in _RELEASED else 0.0

    @property
    def torque(self) -> float:
        """Air-gap torque at the drive time, N m (positive lifts the car)."""
        return float(self._xs[_X_TM])

    @property
    def torque_mean(self) -> float:
        """Mean air-gap torque over the last step, N m (exact for Level 1, trapezoidal for Level 2)."""
        return float(self._xs[_X_TMEAN])

    @property
    def torque_ref(self) -> float:
        """Torque reference of the speed controller at its last tick, N m."""
        return float(self._xs[_X_TREF])

    @property
    def position_ref(self) -> float:
        """Car position reference from the profile, m."""
        return float(self._xs[_X_XREF])

    @property
    def velocity_ref(self) -> float:
        """Car speed reference from the profile, m/s."""
        return float(self._xs[_X_VREF])

    @property
    def acceleration_ref(self) -> float:
        """Car acceleration reference from the profile, m/s²."""
        return float(self._xs[_X_AREF])

    @property
    def speed_ref(self) -> float:
        """Motor speed reference roping * v_ref / R, rad/s (without the position correction)."""
        p = self.params
        return float(self._xs[_X_VREF]) * p.roping / p.sheave_radius

    @property
    def alpha_ref(self) -> float:
        """Motor angular acceleration reference, rad/s²."""
        p = self.params
        return float(self._xs[_X_AREF]) * p.roping / p.sheave_radius

    @property
    def speed_command(self) -> float:
        """Speed-loop set-point incl. the position correction, rad/s (0 when the loop is off)."""
        return float(self._xs[_X_WCMD])

    @property
    def position_error(self) -> float:
        """Car position error (reference - measured) at the last controller tick, m."""
        p = self.params
        return float(self._xs[_X_EPOS]) * p.sheave_radius / p.roping

    @property
    def currents(self) -> tuple[float, float]:
        """Level 2 (i_d, i_q), A (amplitude-invariant dq); zeros for Level 1."""
        return float(self._xs[_X_ID]), float(self._xs[_X_IQ])

    @property
    def voltages(self) -> tuple[float, float]:
        """Level 2 applied (v_d, v_q), V; zeros for Level 1."""
        return float(self._xs[_X_VDA]), float(self._xs[_X_VQA])

    @property
    def dead_time_steps(self) -> int:
        """Level 1 dead time in whole Ts sub-steps (dead_time rounded)."""
        return self._nd

    @property
    def schedule(self) -> list[dict]:
        """Event times (s) and positions (m) of each move."""
        keys = ("t_pretorque", "t_brake_release", "t_profile_start", "t_profile_end", "t_brake_apply",
                "t_ramp_down", "t_torque_off", "x_start", "pretorque", "x_target")
        return [dict(zip(keys, (float(v) for v in row))) for row in self._sched]


# ---------------------------------------------------------------------------------------------------
# The drive FMU's parameters (fmus/reeve_drive_slave.py) and the factory the FMU, the monolithic
# reference and the HIL controller share.

#: R1 pre-torque (N m) for a start at the bottom / top landing with the rated load: the plant's holding
#: torque (`holding_torques`, scenes/elevator_2to1.toml, car.load = 1000 kg), rounded to 0.1 N m
R1_PRETORQUE = (522.5, 331.5)

MAX_LANDINGS = 8    # landing[1..8], pretorque[1..8]
MAX_MOVES = 16      # trip.target[1..16]

# drive FMU parameters: (FMU name, kind, unit, DriveParams field, description, min, max)
# kind: "real" | "int"; special fields: "landing", "pretorque" (per landing, 1-based index),
# "moves" (number of moves alternating between landing[1] and landing[2]), "start_landing" (1-based),
# "n_landings" (landings in use), "target" (explicit move sequence)
DRIVE_PARAMETERS = [
    ("drive.level", "int", None, "level", "drive model: 1 = torque lag + dead time, 2 = PMSM dq model", 1, 2),
    ("trip.v_max", "real", "m/s", "v_max", "rated car speed of the S-curve", 1e-6, None),
    ("trip.a_max", "real", "m/s2", "a_max", "car acceleration limit of the S-curve", 1e-6, None),
    ("trip.jerk", "real", "m/s3", "jerk", "car jerk limit of the S-curve", 1e-6, None),
    *[(f"landing[{k}]", "real", "m", "landing", f"car position at landing {k}", None, None)
      for k in range(1, MAX_LANDINGS + 1)],
    ("trip.landings", "int", None, "n_landings", "number of landings in use (landing[1..n])", 2, MAX_LANDINGS),
    ("trip.start_landing", "int", None, "start_landing", "landing where the car starts (1-based)", 1,
     MAX_LANDINGS),
    ("trip.moves", "int", None, "moves", "number of moves, alternating between landing 1 and 2 (used when "
                                         "trip.target[1] = 0)", 1, 1000),
    *[(f"trip.target[{k}]", "int", None, "target", f"landing of move {k} (1-based; 0 ends the sequence; "
                                                   f"all 0: trip.moves alternating moves)", 0, MAX_LANDINGS)
      for k in range(1, MAX_MOVES + 1)],
    ("trip.start_delay", "real", "s", "start_delay", "time before the first pre-torque", 0.0, None),
    ("trip.dwell_time", "real", "s", "dwell_time", "rest between moves", 0.0, None),
    ("trip.hold_time", "real", "s", "hold_time", "zero-speed hold after the profile", 0.0, None),
    *[(f"pretorque[{k}]", "real", "N.m", "pretorque", f"load-weighing pre-torque for a start at landing {k} "
                                                      f"(set to the holding torque at the load)", None, None)
      for k in range(1, MAX_LANDINGS + 1)],
    ("pretorque.ramp_time", "real", "s", "pretorque_time", "torque ramp to the pre-torque before the "
                                                          "brake lifts", 0.0, None),
    ("torque.ramp_down_time", "real", "s", "torque_ramp_time", "torque ramp to zero after the brake "
                                                               "has dropped", 0.0, None),
    ("brake.lift_delay", "real", "s", "brake_lift_delay", "wait after the release command", 0.0, None),
    ("brake.drop_delay", "real", "s", "brake_drop_delay", "wait after the apply command", 0.0, None),
    ("machine.sheave_radius", "real", "m", "sheave_radius", "traction sheave pitch radius", 1e-6, None),
    ("machine.roping", "real", "1", "roping", "roping factor (rope speed / car speed)", 1e-6, None),
    ("control.J_ff", "real", "kg.m2", "J_ff", "inertia at the motor shaft for the feed-forward", 0.0, None),
    ("control.Kp", "real", "N.m.s/rad", "Kp", "speed PI proportional gain", 0.0, None),
    ("control.Ti", "real", "s", "Ti", "speed PI integral time", 1e-9, None),
    ("control.Kpos", "real", "1/s", "Kpos", "position loop gain", 0.0, None),
    ("control.Ts", "real", "s", "Ts", "speed-loop sample time", 1e-7, None),
    ("torque.max", "real", "N.m", "T_max", "torque limit", 1e-6, None),
    ("torque.power_max", "real", "W", "P_max", "power limit |T w|", 1e-6, None),
    ("torque.tau", "real", "s", "tau_T", "Level 1: first-order torque lag", 0.0, None),
    ("torque.dead_time", "real", "s", "dead_time", "Level 1: dead time (whole control.Ts)", 0.0, None),
    ("pmsm.pole_pairs", "int", None, "pole_pairs", "Level 2: pole pairs", 1, 200),
    ("pmsm.psi", "real", "Wb", "psi", "Level 2: PM flux linkage (amplitude-invariant dq)", 1e-9, None),
    ("pmsm.Rs", "real", "Ohm", "Rs", "Level 2: stator resistance", 1e-9, None),
    ("pmsm.Ld", "real", "H", "Ld", "Level 2: d inductance", 1e-9, None),
    ("pmsm.Lq", "real", "H", "Lq", "Level 2: q inductance", 1e-9, None),
    ("pmsm.V_dc", "real", "V", "V_dc", "Level 2: DC-link voltage (|v_dq| <= V_dc/sqrt 3)", 1e-6, None),
    ("pmsm.Ts_current", "real", "s", "Ts_current", "Level 2: current-loop sample time (divides "
                                                   "control.Ts)", 1e-8, None),
]


def _index(name: str) -> int:
    return int(name[name.index("[") + 1:-1])


#: in-process only (no FMU variable: the drive FMU has no car-position input): shaft information system
SIS_PARAMETERS = {"sis.enabled": ("sis", "1", "1: car-position feedback for the approach"),
                  "sis.resolution": ("sis_resolution", "m", "SIS position quantum"),
                  "sis.delay": ("sis_delay", "s", "SIS measurement age"),
                  "sis.zone": ("sis_zone", "m", "approach length over which the loop blends to the SIS (0: braking distance)"),
                  "sis.filter": ("sis_filter", "s", "low-pass time constant of the SIS - encoder offset")}


def drive_defaults() -> dict:
    """Default drive FMU parameter values: reference set R1 (DriveParams defaults), full travel, one
    round trip, pre-torque for the rated load (R1_PRETORQUE)."""
    p = DriveParams()
    out = {}
    for name, kind, _, field, *_ in DRIVE_PARAMETERS:
        if field == "landing":
            k = _index(name) - 1
            v = list(p.landings)[k] if k < 2 else 0.0
        elif field == "pretorque":
            k = _index(name) - 1
            v = R1_PRETORQUE[k] if k < 2 else 0.0
        elif field == "moves":
            v = len(list(p.moves))
        elif field == "start_landing":
            v = int(p.start_landing) + 1
        elif field == "n_landings":
            v = 2
        elif field == "target":
            v = 0
        else:
            v = getattr(p, field)
        out[name] = int(v) if kind == "int" else float(v)
    return out


def drive_params(values: Optional[Mapping[str, float]] = None):
    """DriveParams from drive FMU parameter values (missing names take `drive_defaults`) and, in
    process, SIS_PARAMETERS."""
    vals = drive_defaults()
    kw = {}
    if values:
        values = dict(values)
        for name, (field, _, _) in SIS_PARAMETERS.items():
            if name in values:
                v = values.pop(name)
                kw[field] = bool(v) if field == "sis" else float(v)
        unknown = set(values) - set(vals)
        if unknown:
            raise ValueError(f"unknown drive parameters {sorted(unknown)}; known: {sorted(vals)} and "
                             f"{sorted(SIS_PARAMETERS)}")
        vals.update(values)
    special = ("landing", "pretorque", "moves", "start_landing", "n_landings", "target")
    for name, kind, _, field, *_ in DRIVE_PARAMETERS:
        if field in special:
            continue
        kw[field] = int(vals[name]) if kind == "int" else float(vals[name])
    nl = int(vals["trip.landings"])
    if not 2 <= nl <= MAX_LANDINGS:
        raise ValueError(f"trip.landings must be 2..{MAX_LANDINGS}, got {nl!r}")
    start = int(vals["trip.start_landing"]) - 1
    if not 0 <= start < nl:
        raise ValueError(f"trip.start_landing must be 1..{nl} (trip.landings), got {vals['trip.start_landing']!r}")
    targets = []
    for k in range(1, MAX_MOVES + 1):
        tg = int(vals[f"trip.target[{k}]"])
        if tg == 0:
            break
        if not 1 <= tg <= nl:
            raise ValueError(f"trip.target[{k}] = {tg}: must name a landing 1..{nl} (trip.landings)")
        targets.append(tg - 1)
    kw["landings"] = tuple(float(vals[f"landing[{k}]"]) for k in range(1, nl + 1))
    kw["start_landing"] = start
    if targets:
        kw["moves"] = tuple(targets)
    else:
        n = int(vals["trip.moves"])
        if nl != 2 or start > 1:
            raise ValueError("trip.moves alternates between landings 1 and 2; with more landings give "
                             "trip.target[1..]")
        kw["moves"] = tuple((start + 1 + i) % 2 for i in range(n))
    kw["pretorque"] = tuple(float(vals[f"pretorque[{k}]"]) for k in range(1, nl + 1))
    return DriveParams(**kw)


def make_drive(values: Optional[Mapping[str, float]] = None):
    """The `ElectricDrive` of the drive FMU for these parameter values."""
    return ElectricDrive(drive_params(values))


def trip_end_time(drive_values: Optional[Mapping[str, float]] = None, settle: float = 1.0) -> float:
    """End of the drive's move sequence (torque off after the last move) plus `settle` seconds."""
    return make_drive(drive_values).t_end + settle
