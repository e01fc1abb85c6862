"""physics.model (issue 31): each preset sets the keys it says, as a scene spelling them out would; keys given
win; a key that cannot work with the model's others is one error naming both; `sphcore keys` shows what each
model sets; the default model runs Buchner's dam break from geometry, sound speed and end time alone; time.end
and time.output_interval in seconds."""
import json
import math

import numpy as np
import pytest

from conftest import schema_keys
from sphcore.cli import main
from sphcore.scene import DEFAULT_MODEL, PRESETS, Scene, SceneError
from sphcore.simulation import Simulation

GEOMETRY = {"domain": {"box_min": [0.0, 0.0], "box_max": [1.0, 0.6]},
            "fluid": {"blocks": [{"min": [0.0, 0.0], "max": [0.25, 0.5]}], "spacing": 0.01, "stiffness": 900.0}}
# each model's keys written out by hand over the graphics model (the scenes' keys before physics.model): the
# engineering model as dam_break_2d.toml spelled it, DFSPH as tank_2d_dfsph.toml did, with time.dt "auto"
SPELLED_OUT = {
    "engineering": {"physics": {"kernel": "wendland_c2", "density": "continuity", "density_diffusion": "molteni",
                                "viscosity_model": "artificial"},
                    "fluid": {"smoothing_ratio": 4.0, "density_diffusion": 0.1, "alpha": 0.01},
                    "time": {"integrator": "verlet", "dt": "adaptive"}},
    "dfsph": {"physics": {"pressure_solver": "dfsph", "kernel": "wendland_c2"}, "fluid": {"relaxation": 0.8},
              "time": {"dt": "auto"}},
    "graphics": {},
}


def scene_of(*tables):
    """A scene from nested dicts merged table by table (later ones win)."""
    data = {}
    for t in tables:
        for k, v in t.items():
            data[k] = {**data.get(k, {}), **v} if isinstance(v, dict) else v
    return Scene.from_dict(data)


def folded(scene):
    """What a run compiles and pushes: the spec and the parameter block's bytes."""
    return scene.spec, scene.params(len(scene.initial_positions())).tobytes()


@pytest.mark.parametrize("model", list(PRESETS))
def test_a_model_folds_as_its_keys_spelled_out(model):
    named = scene_of(GEOMETRY, {"physics": {"model": model}})
    spelled = scene_of(GEOMETRY, {"physics": {"model": "graphics"}}, SPELLED_OUT[model])
    assert folded(named) == folded(spelled)
    assert {k: named[k] for k in PRESETS[model]} == {k: spelled[k] for k in PRESETS[model]}


def test_every_model_sets_the_same_keys_and_the_defaults_are_the_default_models():
    keys = dict(schema_keys())
    assert DEFAULT_MODEL == "engineering" == keys["physics.model"].default
    assert keys["physics.model"].kind.split("|") == list(PRESETS)
    for model, values in PRESETS.items():
        assert values.keys() == PRESETS[DEFAULT_MODEL].keys(), model
        scene = Scene.from_dict({"physics": {"model": model}})  # accepted: a model's own keys go together
        assert {k: scene[k] for k in values} == values
    assert {k: keys[k].default for k in PRESETS[DEFAULT_MODEL]} == PRESETS[DEFAULT_MODEL]
    assert folded(Scene.from_dict({})) == folded(Scene.from_dict({"physics": {"model": DEFAULT_MODEL}}))


def test_the_shipped_engineering_scenes_are_the_model_spelled_out():
    """dam_break_2d.toml names the model in place of its keys; dam_break_3d.toml overrides two of them."""
    shipped = Scene.load("dam_break_2d")
    assert shipped["physics.model"] == "engineering"
    spelled = scene_of(GEOMETRY, {"name": "dam_break_2d", "physics": {"model": "graphics"}}, SPELLED_OUT["engineering"])
    assert folded(shipped) == folded(spelled)
    three = Scene.load("dam_break_3d")
    assert (three["fluid.smoothing_ratio"], three["fluid.alpha"], three["physics.kernel"]) == (2.857, 0.02, "wendland_c2")
    dfsph = Scene.load("tank_2d_dfsph")
    assert dfsph["physics.model"] == "dfsph" and dfsph.dt > 10 * PRESETS["graphics"]["time.dt"]


def test_the_validation_engineering_configuration_is_the_engineering_model():
    from sphcore.validate import configs

    over_graphics = scene_of(GEOMETRY, configs.apply({"physics": {"model": "graphics"}},
                                                     {**configs.ENGINEERING, "time.dt": "adaptive"}))
    assert folded(over_graphics) == folded(scene_of(GEOMETRY, {"physics": {"model": "engineering"}}))


def test_keys_given_override_the_model():
    scene = scene_of(GEOMETRY, {"physics": {"model": "engineering", "equation_of_state": "tait"},
                                "fluid": {"smoothing_ratio": 2.857, "alpha": 0.02}, "time": {"dt": "auto"}})
    assert (scene["fluid.smoothing_ratio"], scene["fluid.alpha"], scene["time.dt"]) == (2.857, 0.02, "auto")
    assert (scene["physics.kernel"], scene["time.integrator"]) == ("wendland_c2", "verlet")  # the rest: the model's
    graphics = scene_of(GEOMETRY, {"physics": {"model": "graphics", "kernel": "wendland_c2"}})
    assert graphics.spec.KERNEL == 1 and graphics["fluid.smoothing_ratio"] == 2.0


def test_a_scene_round_trips_through_json():
    for model in PRESETS:
        scene = scene_of(GEOMETRY, {"physics": {"model": model}})
        again = Scene.from_dict(json.loads(scene.to_json()))
        assert again == scene and folded(again) == folded(scene) and scene.validated() == scene


# (scene, the keys the one message names, the mend it proposes)
CONFLICTS = [
    ({"physics": {"model": "dfsph", "density": "continuity"}},
     ["physics.pressure_solver", 'physics.model = "dfsph"', 'physics.density = "continuity"'], None),
    ({"physics": {"model": "dfsph"}, "time": {"integrator": "verlet"}},
     ["physics.pressure_solver", 'physics.model = "dfsph"', 'time.integrator = "verlet"'], None),
    # the trap: the solver switched on in a scene of the default model, its three refusals in one
    ({"physics": {"pressure_solver": "dfsph"}},
     ['physics.pressure_solver = "dfsph"', 'physics.density = "continuity"', 'time.integrator = "verlet"',
      'physics.model = "engineering", the default'], {"physics": {"model": "dfsph"}}),
    ({"physics": {"density": "summation"}},
     ['physics.density = "summation"', 'physics.density_diffusion = "molteni"', 'physics.model = "engineering"'],
     {"physics": {"density": "summation", "density_diffusion": "none"}}),
    ({"physics": {"model": "graphics", "density_diffusion": "fourtakas"}},
     ['physics.density_diffusion = "fourtakas"', 'physics.density = "summation"', 'physics.model = "graphics"'],
     {"physics": {"model": "graphics", "density_diffusion": "fourtakas", "density": "continuity"}}),
    ({"physics": {"model": "dfsph", "list_skin": 0.1}},
     ["physics.list_skin = 0.1", 'physics.pressure_solver = "dfsph"', 'physics.model = "dfsph"'], None),
]


@pytest.mark.parametrize("data, named, mended", CONFLICTS, ids=[str(c[0]) for c in CONFLICTS])
def test_a_conflict_is_one_error_naming_both_keys_and_the_model(data, named, mended):
    with pytest.raises(SceneError) as e:
        scene_of(GEOMETRY, data)
    message = str(e.value)
    assert "\n" not in message
    for text in named:
        assert text in message, (text, message)
    if mended is not None:  # what the message proposes is accepted
        scene_of(GEOMETRY, mended)


def test_an_unknown_model_is_refused_naming_the_choices():
    with pytest.raises(SceneError, match=r"physics\.model = 'sph': choose one of 'graphics', 'engineering', 'dfsph'"):
        Scene.from_dict({"physics": {"model": "sph"}})


def test_keys_lists_each_models_values(capsys):
    assert main(["keys"]) == 0
    lines = {line.split()[0]: line for line in capsys.readouterr().out.splitlines()[1:] if line.strip()}
    assert "graphics|engineering|dfsph" in lines["physics.model"]
    for dotted in PRESETS[DEFAULT_MODEL]:
        listed = ", ".join(f"{m} {json.dumps(PRESETS[m][dotted])}" for m in PRESETS)
        assert lines[dotted].endswith(f"(physics.model: {listed})"), lines[dotted]
    assert lines["time.dt"].endswith('(physics.model: graphics 0.0001, engineering "adaptive", dfsph "auto")')
    assert "physics.model" not in lines["fluid.spacing"]  # a key no model sets lists none


# ---- time.end and time.output_interval ----

def test_time_in_seconds():
    scene = scene_of(GEOMETRY, {"time": {"end": 0.75, "output_interval": 0.05}})
    assert (scene.end_time, scene.output_interval) == (0.75, 0.05)
    assert (scene["time.steps"], scene["time.output_every"]) == (0, 0)  # the counts are not what ends the run
    assert Scene.from_dict(json.loads(scene.to_json())) == scene and scene.validated() == scene
    steps = Scene.load("dam_break_2d")
    assert (steps.end_time, steps.output_interval, steps["time.steps"], steps["time.output_every"]) == (None, None,
                                                                                                        2500, 100)
    default = Scene.from_dict({})
    assert (default.end_time, default["time.steps"], default["time.output_every"]) == (None, 5000, 250)
    mixed = scene_of(GEOMETRY, {"time": {"end": 0.75, "output_every": 10}})
    assert (mixed.end_time, mixed.output_interval, mixed["time.output_every"]) == (0.75, None, 10)


@pytest.mark.parametrize("time, named", [
    ({"end": 1.0, "steps": 100}, ["time.end = 1 s", "time.steps = 100"]),
    ({"output_interval": 0.1, "output_every": 5}, ["time.output_interval = 0.1 s", "time.output_every = 5"]),
    ({"steps": 0}, ["time.steps = 0", "time.end"]),
    ({"output_every": 0}, ["time.output_every = 0", "time.output_interval"]),
    ({"end": -1.0}, ["time.end = -1.0", "[0, 1e+09] s"]),
    ({"output_interval": "1 s"}, ["time.output_interval", "expected a number"]),
])
def test_time_keys_are_checked(time, named):
    with pytest.raises(SceneError) as e:
        scene_of(GEOMETRY, {"time": time})
    for text in named:
        assert text in str(e.value), (text, str(e.value))


# ---- the default survives ----

def test_the_default_model_runs_buchners_dam_break_from_geometry_sound_speed_and_end_time():
    """benchmarks/default_model.py at dx = H / 10 (200 particles): only the box, the column, the spacing, the
    sound speed c = 20 sqrt(g H) and time.end = 7 / sqrt(g / H) given, the run reaches time.end without a
    blow-up (Simulation's checks: finite values, bounded energy and speed, every particle in the box), and the
    water has reached the far wall and not left the tank's lower half."""
    H, g = 0.6, 9.81
    scene = Scene.from_dict({
        "domain": {"box_max": [3.22, 4.0]},
        "fluid": {"blocks": [{"min": [0.0, 0.0], "max": [2 * H, H]}], "spacing": H / 10,
                  "stiffness": (20.0 * math.sqrt(g * H)) ** 2},
        "time": {"end": 7.0 / math.sqrt(g / H)},
    })
    assert scene["physics.model"] == DEFAULT_MODEL
    with Simulation(scene, "numba") as sim:
        while sim.time < scene.end_time:
            sim.advance(100)
            x = sim.read()["particle_x"][:, :2]  # each read runs the blow-up checks
        assert np.isfinite(x).all()
    assert x[:, 0].max() > 3.22 - 2 * scene["fluid.spacing"] and x[:, 1].max() < 2.0
