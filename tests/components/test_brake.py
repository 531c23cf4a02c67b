"""Machine brake of the plant against the rigid-body closed form: a balanced 1:1 hoist (2 x 500 kg on a
0.2 m traction sheave, motor inertia 2 kg m^2, stiff rope: J = 2 + 1000 * 0.2^2 = 42 kg m^2) runs at
~4.85 rad/s; the brake (420 N m, first-order engagement tau = 20 ms) is applied at t = 1 s with the motor
torque off. Slipping, the brake torque is T_b e(t), e = 1 - exp(-(t-1)/tau): the deceleration is T_b/J
once engaged, the sheave stops at omega(1) = (T_b/J) (s - tau (1 - exp(-s/tau))), s = t_stop - 1, and
then sticks (the elasto-plastic brake holds, no creep)."""
import math

import numpy as np
from scipy.optimize import brentq

from reeve_fmu.components.plant import Plant
from reeve_fmu.core.scene import loads_scene
from tests.support.checks import check

HOIST = """
[scene]
name = "brake_stop"
model = "axial-1d"
[solver]
step = 1e-4
rho_inf = 1.0
newton_tol = 1e-10
[initial]
statics = "positions"
[[bodies]]
name = "car"
mass = 500.0
position = [-0.2, 0.0, 0.0]
free = ["z"]
[[bodies]]
name = "counterweight"
mass = 500.0
position = [0.2, 0.0, 0.0]
free = ["z"]
[[sheaves]]
name = "traction"
kind = "traction"
center = [0.0, 0.0, 20.0]
radius = 0.2
inertia = 0.0
[[ropes]]
name = "rope"
EA = 1.0e9
rhoA = 1e-3
route = [
  { anchor = "car", at = [0.0, 0.0, 0.0] },
  { sheave = "traction", wrap = "cw" },
  { anchor = "counterweight", at = [0.0, 0.0, 0.0] },
]
[drive]
kind = "external"
sheave = "traction"
motor_inertia = 2.0
[brake]
torque = 420.0
stick_angle = 1e-4
engage_time = 0.02
"""


def test_brake_stop_decelerates_at_T_over_J_then_sticks():
    p = Plant(loads_scene(HOIST, "brake_stop.toml"))
    rows = [(p.t, *p.step(1e-3, 210.0, 1.0)) for _ in range(1000)]      # brake released, accelerate
    rows += [(p.t, *p.step(1e-3, 0.0, 0.0)) for _ in range(1000)]       # torque off, brake applied
    a = np.array(rows)
    t = a[:, 0]
    col = {n: a[:, i + 1] for i, n in enumerate(p.output_names)}
    th, w = col["motor.angle"], col["motor.speed"]
    J, Tb, tau = 2.0 + 1000.0 * 0.2 ** 2, 420.0, 0.02
    slip = (t > 1.1) & (t < 1.45)                   # slipping, engaged: the brake torque is -T_b e(t)
    e = 1 - np.exp(-(t[slip] - 1.0) / tau)
    check('col["brake.torque"][slip] + Tb * e', col["brake.torque"][slip] + Tb * e, 3e-3 * Tb)
    # mean deceleration over the engaged window from the angle (second difference over 0.15 s; the
    # stiff rope rings at ~50 Hz, which the average removes)
    alpha = -(np.interp(1.4, t, th) - 2 * np.interp(1.25, t, th) + np.interp(1.1, t, th)) / 0.15 ** 2
    check('alpha / (Tb / J) - 1', alpha / (Tb / J) - 1, 0.00061)
    w1 = np.interp(1.0, t, w)
    assert w1 > 4.5
    t_stop = 1.0 + brentq(lambda s: w1 - Tb / J * (s - tau * (1 - math.exp(-s / tau))), 0.01, 2.0)
    i = np.argmax((t > 1.0) & (w <= 0.0))
    check('t[i] - t_stop', t[i] - t_stop, 5e-3)
    # stuck: the angle rings on the brake spring around the stop, by no more than twice its stick
    # deflection either way (a slipping brake would leave the angle running on), no creep over 0.4 s
    after = t > t_stop + 0.05
    check("motor angle range after the stop [rad]", np.ptp(th[after]), 4e-4)
    check('np.mean(th[after][-100:]) - np.mean(th[after][:100])', np.mean(th[after][-100:]) - np.mean(th[after][:100]), 1e-4)


def test_step_to_event_ends_at_the_solver_step_of_the_brake_half_engagement():
    """Plant.step_to_event (the FMI 3.0 early return): the brake's engagement is e(t) = 1 - exp(-(t - t_c)/tau)
    after the command at t_c, so it crosses 1/2 at t_c + tau ln 2; a 50 ms step ends at the end of the
    solver step (0.1 ms) that contains that time, released at t_c = 0 and applied at t_c = 1 s. A step
    without an event is step()'s bit for bit."""
    tau, h = 0.02, 1e-4
    p = Plant(loads_scene(HOIST, "brake_stop.toml"))
    y, t1, event = p.step_to_event(0.05, 210.0, 1.0)
    assert event == "the brake releases"
    ulps = "the reached time is t0 + k (dt / n): two ulps of 1 s"
    check("t1 - (solver step end after tau ln 2)", t1 - math.ceil(tau * math.log(2) / h) * h, 4.4e-16, ulps)
    assert p.t == t1 and p.output("brake.engaged") < 0.5
    q = Plant(loads_scene(HOIST, "brake_stop.toml"))
    q.set_state(p.get_state())
    while p.t < 1.0 - 1e-9:                        # no event: step_to_event is step()
        dt = min(0.05, 1.0 - p.t)
        y, t, event = p.step_to_event(dt, 210.0, 1.0)
        assert event is None and t == p.t and np.array_equal(y, q.step(dt, 210.0, 1.0))
    check("p.t - 1", p.t - 1.0, 4.4e-16, ulps)
    y, t2, event = p.step_to_event(0.05, 0.0, 0.0)
    assert event == "the brake engages"
    assert t2 == p.t and p.output("brake.engaged") >= 0.5
    check("t2 - 1 - ceil(tau ln 2 / h) h", t2 - 1.0 - math.ceil(tau * math.log(2) / h) * h, 4.4e-16, ulps)
