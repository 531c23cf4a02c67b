"""Bad scenes get an error naming the file, the key and the problem; shipped scenes load."""
import pytest

from reeve_fmu.core.model import build_model
from reeve_fmu.core.scene import SceneError, load_scene, loads_scene
from tests.support import ROOT

SCENES = sorted((ROOT / "scenes").glob("*.toml"))

BASE = """
[scene]
model = "axial-1d"
[[bodies]]
name = "mass"
mass = 100.0
[[ropes]]
name = "rope"
EA = 1e6
rhoA = 0.5
length = 10.0
route = [ { anchor = "ground", at = [0, 0, 10] }, { anchor = "mass", at = [0, 0, 0] } ]
[initial]
statics = "rope-length"
"""


def test_shipped_scenes_load_and_build():
    assert len(SCENES) >= 3
    for p in SCENES:
        sc = load_scene(p)
        if "crane" in sc.extra:
            from reeve_fmu.studies.crane import build_crane
            build_crane(sc)             # the dynamic model and the crane's parts in it
        else:
            build_model(sc)


@pytest.mark.parametrize("old,new,key,problem", [
    ("EA = 1e6", "EA = -1e6", "ropes[0].EA", "must be > 0"),
    ("EA = 1e6", 'EA = "stiff"', "ropes[0].EA", "must be a number"),
    ("mass = 100.0", "", "bodies[0]", "missing required key 'mass'"),
    ('model = "axial-1d"', 'model = "4d"', "scene.model", "must be one of"),
    ('anchor = "mass"', 'anchor = "car"', "ropes[0].route[1].anchor", "must be 'ground' or a body name"),
    ("length = 10.0", "", "ropes[0].length", "needs each rope's unstretched length"),
    ("rhoA = 0.5", "rhoA = 0.5\ncolour = 1", "ropes[0]", "unknown key(s) 'colour'"),
])
def test_bad_scene_names_key(old, new, key, problem):
    text = BASE.replace(old, new)
    with pytest.raises(SceneError) as exc:
        loads_scene(text, "bad.toml")
    msg = str(exc.value)
    assert msg.startswith("bad.toml: ")
    assert f"[{key}]" in msg
    assert problem in msg


def test_invalid_toml_and_missing_file(tmp_path):
    p = tmp_path / "x.toml"
    p.write_text("[scene\n", encoding="utf-8")
    with pytest.raises(SceneError, match=r"x.toml: invalid TOML"):
        load_scene(p)
    with pytest.raises(SceneError, match="cannot read scene file"):
        load_scene(tmp_path / "missing.toml")


def test_positions_statics_count_mismatch_is_explained():
    text = BASE.replace('statics = "rope-length"', 'statics = "positions"').replace(
        '[[ropes]]', '[[bodies]]\nname = "b2"\nmass = 1.0\n[[ropes]]')
    with pytest.raises(SceneError, match=r"\[initial.statics\] 'positions'"):
        build_model(loads_scene(text, "s.toml"))


def test_unknown_sheave_and_reuse():
    text = BASE.replace('{ anchor = "mass", at = [0, 0, 0] }', '{ sheave = "nope" }, { anchor = "mass", at = [0, 0, 0] }')
    with pytest.raises(SceneError, match=r"route\[1\].sheave\] unknown sheave 'nope'"):
        loads_scene(text, "s.toml")


TWO_FALL = (ROOT / "scenes" / "crane_two_fall.toml").read_text(encoding="utf-8")


@pytest.mark.parametrize("old,new,key,problem", [
    ("rhoA = 2.4 ", 'rhoA = 2.4\nelement = "cubic"\nEI = 10.0\nwrap_model = "W2"\n', "ropes[0].wrap_model",
     "'W2' cannot hold its cubic wrap elements with exact tangent points"),
    ('at = [0.25, 0.0, 0.0] }', 'at = [0.25, 0.0, 0.0], hitch_stiffness = 1e6 }', "ropes[0].route[3].hitch_stiffness",
     "a hitch spring is not available with exact tangent points"),
    ('at = [0.25, 0.0, 0.0] }', 'at = [0.25, 0.0, 0.0], hitch_damping = 1e3 }', "ropes[0].route[3].hitch_damping",
     "a hitch spring is not available with exact tangent points"),
])
def test_exact_tangents_refuse_what_they_cannot_hold(old, new, key, problem):
    """The hook block turns (exact tangent points): a W2 wrap or a hitch spring is refused at the key."""
    assert old in TWO_FALL
    with pytest.raises(SceneError) as exc:
        loads_scene(TWO_FALL.replace(old, new, 1), "bad.toml")
    msg = str(exc.value)
    assert msg.startswith(f"bad.toml: [{key}] ") and problem in msg, msg
