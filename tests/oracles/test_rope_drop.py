"""A load dropped onto a slack rope (a rope as scenes give it: tension-only by default) against the energy
balance of a mass on a massless spring, and the rope verdicts of the drop: a slack rope reports 0 N (not
the span's weight share as a negative force), the slack verdict WARNs with the slack times, the snap load
is judged against the rope's breaking force, the energy is conserved through slack/taut cycles, and a
bilateral rope (tension_only = false) that pushes is a FAIL."""
import math
from dataclasses import replace

import numpy as np
import pytest

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

from reeve_fmu.core.model import build_model
from reeve_fmu.core.scene import parse_scene
from reeve_fmu.core.solver import Simulator, SolverError
from reeve_fmu.studies.verdicts import scene_verdicts
from tests.support.checks import check

G, MASS, EA, L, DROP = 9.81, 500.0, 2.9e6, 50.0, 1.0

# 500 kg held 1 m above the reach of a 50 m rope (nearly massless: 0.05 kg), released at rest
DROP_SCENE = f'''
[scene]
name = "drop"
model = "axial-1d"
t_end = 1.5
[solver]
step = 1e-4
rho_inf = 1.0
[initial]
statics = "none"
[[bodies]]
name = "mass"
mass = {MASS}
position = [0.0, 0.0, {DROP}]
free = ["z"]
[[ropes]]
name = "rope"
EA = {EA}
rhoA = 0.001
length = {L}
breaking_force = 60e3
route = [
  {{ anchor = "ground", at = [0.0, 0.0, {L}] }},
  {{ anchor = "mass", at = [0.0, 0.0, 0.0] }},
]
'''


@pytest.fixture(scope="module")
def drop():
    sc = parse_scene(tomllib.loads(DROP_SCENE), "drop.toml")
    res = Simulator(build_model(sc)).run(1.5, 1e-3)
    return sc, res, {n: np.asarray(res[n]) for n in res.names}


def test_drop_peak_force_is_the_energy_balance(drop):
    """Free fall h, then the rope (k = EA/L) stops the mass: m g (h + x) = k x^2 / 2, peak k x =
    m g + sqrt((m g)^2 + 2 k m g h); the rope is slack (0 N, never negative) until t = sqrt(2 h / g)."""
    sc, res, c = drop
    mg, k = MASS * G, EA / L
    peak = mg + math.sqrt(mg * mg + 2.0 * k * mg * DROP)
    F = c["rope.tension_start"]
    # measured 5.0e-5 in magnitude (the rope's 0.05 kg against 500 kg, the 1 ms output sampling of the peak)
    check("drop: peak rope force / energy balance - 1", F.max() / peak - 1.0, 2e-4)
    assert F.min() == 0.0 and c["rope.tension_end"].min() == 0.0
    caught = res.time[np.flatnonzero(F > 0.0)[0]]
    # measured 4.8e-4 s: the first output sample after the catch (outputs every 1 ms)
    check("drop: time the rope comes taut - sqrt(2 h / g) [s]", caught - math.sqrt(2.0 * DROP / G), 1e-3,
          reason="the output step (1 ms) is the resolution")


def test_drop_verdicts(drop):
    sc, res, c = drop
    vs = {v.check: v for v in scene_verdicts(sc, res.time, c)}
    slack = vs["slack rope (minimum rope force)"]
    assert slack.status == "WARN" and "rope.tension_start 0.000-0.451 s" in slack.note, slack.line()
    snap = vs["snap load after slack (rope)"]
    assert snap.status == "PASS" and snap.value == c["rope.tension_start"].max()
    weak = replace(sc, ropes=(replace(sc.ropes[0], breaking_force=25e3),))      # below the 29.3 kN peak
    assert [v.status for v in scene_verdicts(weak, res.time, c) if v.check.startswith("snap")] == ["FAIL"]


def test_drop_energy_is_conserved_through_slack_and_taut():
    """No damping, rho_inf = 1 (no numerical dissipation): the mass falls slack, the rope catches it and
    throws it back up slack, and it is caught again; the only external force is gravity, whose work is
    in the energy, so kinetic + gravity + strain energy stays at its start value. The smoothed slack law
    is conservative (a force with its energy): what remains is the integrator's error at the two
    catches and releases."""
    sc = parse_scene(tomllib.loads(DROP_SCENE), "drop.toml")
    sim = Simulator(build_model(sc))
    st = sim.initial_state()
    E0 = sum(sim.energy(st))
    res = sim.run(1.9, 1e-3, state=st)
    F = np.asarray(res["rope.tension_start"])
    taut = F > 0.0
    # slack, taut, slack, taut: two catches and a release in the record
    edges = np.diff(taut.astype(int))
    assert np.count_nonzero(edges == 1) == 2 and np.count_nonzero(edges == -1) == 1
    assert F.min() == 0.0
    E1 = sum(sim.energy(sim.final_state))
    check("energy after two catches - start, / (m g h)", (E1 - E0) / (MASS * G * DROP), 1e-6)


def test_a_bilateral_rope_pushes_and_fails():
    """The same drop with a bilateral rope: the 2 % short rope pushes the mass down (EA eps = -58 kN at
    the start); the outputs show that force and the slack verdict FAILs it."""
    sc = parse_scene(tomllib.loads(DROP_SCENE.replace("breaking_force", "tension_only = false\nbreaking_force")), "drop.toml")
    res = Simulator(build_model(sc)).run(0.05, 1e-3)
    c = {n: np.asarray(res[n]) for n in res.names}
    check("bilateral: start force / EA eps - 1", c["rope.tension_start"][0] / (EA * (-DROP / L)) - 1.0, 1e-12,
          reason="exact here (the strain of the scene's positions); round-off in general")
    v = next(v for v in scene_verdicts(sc, res.time, c) if v.check.startswith("slack"))
    assert v.status == "FAIL" and "the rope model pushed" in v.note


# a hook on a rope over a jib-tip sheave, let go from where the rope lies 0.53 m slack (the scene's
# positions, no statics): every span of the rope is shorter than its material at the start
CRANE_DROP = '''
[scene]
name = "crane_drop"
model = "planar"
sheave_contact = "rigid"
[solver]
step = 1e-3
[initial]
statics = "none"
[[bodies]]
name = "hook"
mass = 200.0
position = [10.3, 0.0, 12.0]
free = ["x", "z"]
[[sheaves]]
name = "tip"
center = [10.0, 0.0, 20.0]
radius = 0.3
[[ropes]]
name = "hoist"
EA = 5e6
rhoA = 0.5
length = 19.0
breaking_force = 50e3
route = [
  { anchor = "ground", at = [0.0, 0.0, 20.3] },
  { sheave = "tip", wrap = "cw" },
  { anchor = "hook", at = [0.0, 0.0, 0.0] },
]
'''


@pytest.mark.parametrize("tonly", ["", "tension_only = false"], ids=["default", "bilateral"])
def test_crane_hook_let_go_on_a_slack_rope(tonly):
    """The default rope goes slack: every rope force output is >= 0 (0 while slack), the slack verdict
    WARNs with the slack times (the first from t = 0 until the hook has fallen the slack, ~0.3 s) and
    the snap load is below the breaking force: no FAIL. A bilateral rope pushes the hook down (every
    output negative at the start) and its slack verdict FAILs with the reason."""
    sc = parse_scene(tomllib.loads(CRANE_DROP.replace("breaking_force", tonly + "\nbreaking_force")), "crane.toml")
    res = Simulator(build_model(sc)).run(0.6 if not tonly else 0.05, 1e-3)
    c = {n: np.asarray(res[n]) for n in res.names}
    tens = [n for n in c if ".tension_" in n]
    assert len(tens) == 4
    vs = {v.check: v for v in scene_verdicts(sc, res.time, c)}
    slack = vs["slack rope (minimum rope force)"]
    if tonly:
        assert all(c[n][0] < -1e5 for n in tens), {n: c[n][0] for n in tens}
        assert slack.status == "FAIL" and "tension_only = false" in slack.note, slack.line()
    else:
        assert min(c[n].min() for n in tens) == 0.0 and all(c[n][0] == 0.0 for n in tens)
        t0 = {n: float(res.time[np.flatnonzero(c[n] > 0.0)[0]]) for n in tens}
        assert all(0.25 < t < 0.35 for t in t0.values()), t0        # free fall of 0.53 m: 0.33 s
        assert slack.status == "WARN" and "hoist.tension_start 0.000-0.3" in slack.note, slack.line()
        assert vs["snap load after slack (hoist)"].status == "PASS"
        assert not [v.line() for v in vs.values() if v.status == "FAIL"]


STRUT = '''
[scene]
name = "strut"
model = "axial-1d"
[initial]
statics = "rope-length"
[[bodies]]
name = "mass"
mass = 10.0
position = [0.0, 0.0, 1.0]
free = ["z"]
[[ropes]]
name = "rope"
EA = 1e6
rhoA = 0.01
length = 1.0
route = [ { anchor = "ground", at = [0.0, 0.0, 0.0] }, { anchor = "mass", at = [0.0, 0.0, 0.0] } ]
'''


def test_a_rope_that_would_have_to_push_in_the_statics_is_an_error():
    """A mass resting on a rope below it: only a strut holds it. The default (tension-only) rope's
    initial statics stops with an error naming the rope and span; a bilateral rope holds the mass
    as a strut and reports that push as a negative force, its axial force EA eps = -(m g + rhoA L g / 2)
    (the element's mean: the mass on top, half the rope's weight)."""
    sc = parse_scene(tomllib.loads(STRUT), "strut.toml")
    with pytest.raises(SolverError) as exc:
        Simulator(build_model(sc)).initial_state()
    assert "rope 'rope' span 0 would be in compression" in str(exc.value), str(exc.value)
    sc = parse_scene(tomllib.loads(STRUT.replace("length = 1.0", "length = 1.0\ntension_only = false")), "strut.toml")
    sim = Simulator(build_model(sc))
    y = dict(zip(sim.model.output_names, sim.outputs(sim.initial_state())))
    check("strut force / -(m g + rhoA L g / 2) - 1", y["rope.tension_end"] / -(10.0 * G + 0.005 * G) - 1.0, 5e-12,
          reason="the statics converge to round-off")
