"""Neighbour lists reused between builds (physics.list_skin, shaders/sph/cells.glsl: list_reach): a build sorts the
particles and lists every pair within (1 + skin) h; later steps walk those lists until a particle has moved far
enough that a pair within h might be missing. Checked here against all pairs at the steps that reuse them, against
runs that build every step, between the backends, through a checkpoint, and the key's bad values.
"""
import copy

import numpy as np
import pytest

from conftest import BACKENDS, scene_changed, vulkan_or_skip
from reference import density_pressure, neighbours
from sphcore.backends import REUSE, Stage, list_entries
from sphcore.cli import main
from sphcore.profile import Profile
from sphcore.scene import SceneError
from sphcore.simulation import Simulation
from sphcore.sph.dfsph import CONTROL_BUILDS, CONTROL_REBUILD, IMAGE_SHIFT, NEIGHBOUR_MASK

# a 2D water column (20 x 30 particles) collapsing in a 0.6 m x 0.4 m tank: by step 240 it has hit the far wall's
# corner region and moves at about 1 m/s, 0.01 h a step (a build every ten steps or so at skin 0.2)
SCENE = {
    "name": "skin",
    "physics": {"model": "graphics", "equation_of_state": "tait", "list_skin": 0.2},
    "domain": {"box_min": [0.0, 0.0], "box_max": [0.6, 0.4]},
    "fluid": {"spacing": 0.01, "blocks": [{"min": [0.0, 0.0], "max": [0.2, 0.3]}], "stiffness": 900.0,
              "viscosity": 0.5},
    "time": {"dt": 2e-4},
}
SCENE_3D = {
    "name": "skin3d",
    "physics": {"model": "graphics", "dimension": 3, "equation_of_state": "tait", "list_skin": 0.25},
    "domain": {"box_min": [0.0, 0.0, 0.0], "box_max": [0.4, 0.3, 0.2]},
    "fluid": {"spacing": 0.02, "blocks": [{"min": [0.0, 0.0, 0.0], "max": [0.16, 0.2, 0.2]}], "stiffness": 900.0,
              "viscosity": 0.5},
    "forces": {"gravity": [0.0, -9.81, 0.0]},
    "time": {"dt": 4e-4},
}
# the same in a channel 2.4 h deep, whose walls are both within reach of a build's (1 + 0.2) h: each particle keeps
# the wall it was near at the build (Scene refuses a channel narrower than (2 + 1.5 list_skin) h)
SCENE_NARROW = copy.deepcopy(SCENE_3D)
SCENE_NARROW["physics"]["list_skin"] = 0.2
SCENE_NARROW["domain"]["box_max"][2] = SCENE_NARROW["fluid"]["blocks"][0]["max"][2] = 0.096
# the engineering model's switches (scenes/dam_break_2d.toml's, on these scenes' 2 dx support): continuity density with
# density diffusion, whose walks add each pair's rate; kick-drift-kick Verlet and the device's adaptive dt; in 3D the
# hydrostatic diffusion of Fourtakas et al.
ENGINEERING = {"kernel": "wendland_c2", "density": "continuity", "density_diffusion": "molteni",
               "viscosity_model": "artificial"}
SCENE_CONTINUITY = copy.deepcopy(SCENE)
SCENE_CONTINUITY["physics"].update(ENGINEERING)
SCENE_CONTINUITY["time"] = {"integrator": "verlet", "dt": "adaptive"}
SCENE_CONTINUITY_4DX = copy.deepcopy(SCENE_CONTINUITY)  # (its support, 4 dx: cells of h / 2, Scene.cell_split)
SCENE_CONTINUITY_4DX["fluid"]["smoothing_ratio"] = 4.0
SCENE_CONTINUITY_3D = copy.deepcopy(SCENE_3D)
SCENE_CONTINUITY_3D["physics"].update(ENGINEERING, density_diffusion="fourtakas")
SCENE_CONTINUITY_3D["time"] = {"integrator": "verlet", "dt": "adaptive"}
READ = ("particle_x", "particle_id", "particle_rho", "neighbours", "neighbour_count", "control")


def scene_of(base=SCENE, **changes):
    return scene_changed(base, **changes)


def backend_or_skip(backend):
    if backend == "vulkan":
        vulkan_or_skip()


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("max_neighbours", [0, 12])
def test_reused_lists_hold_every_pair_within_h_and_give_the_all_pairs_density(backend, max_neighbours):
    """After every 6th step whose next step walks the lists: every particle and wall image within h of a particle
    (all pairs, tests/reference.py) is in its list, and the densities the walks summed are the all-pairs ones. With
    12 slots most lists overflow at their build: those particles scan the build's cells instead, and their density
    must be right too. The lists must actually be reused: fewer builds than steps, and checks made 3 or more
    steps after a build."""
    backend_or_skip(backend)
    scene = scene_of(**{"physics.kernel": "mueller", "fluid.max_neighbours": max_neighbours})
    h, lo, hi = scene.h, np.array(scene["domain.box_min"]), np.array(scene["domain.box_max"])
    checked, since_build, last_builds = [], 0, None
    with Simulation(scene, backend) as sim:
        spec = sim.spec
        for step in range(1, 241):
            sim.advance(1)
            state = sim.backend.read(READ)  # (not sim.read(): a read of the state asks for a build)
            builds = int(state["control"][CONTROL_BUILDS])
            since_build = 0 if builds != last_builds else since_build + 1
            last_builds = builds
            if state["control"][CONTROL_REBUILD] or step % 6:
                continue
            x = state["particle_x"][:, :2].astype(np.float64)
            lists, count = list_entries(state, spec), state["neighbour_count"]
            for i, expected in enumerate(neighbours(x, h, lo, hi)):
                if count[i] > spec.MAX_NEIGHBOURS:
                    continue
                listed = {(int(e & NEIGHBOUR_MASK), tuple(-1.0 if e >> IMAGE_SHIFT & 1 << a else 1.0 for a in range(2)))
                          for e in lists[i, :count[i]]}  # (the reference's images: their flips, -1 on a mirrored axis)
                assert expected <= listed, (step, i, sorted(expected - listed))
            # the density the next step walks (the walk of this step summed it at these positions' predecessors):
            # run it again now, as the next step will
            sim.backend.run_stage(Stage("compute_density", 1, when=REUSE))
            rho = sim.backend.read_buffer("particle_rho").astype(np.float64)
            expected_rho, _ = density_pressure(x, scene.mass, h, scene["fluid.rest_density"], scene["fluid.stiffness"],
                                               lo, hi, tait=True)
            np.testing.assert_allclose(rho, expected_rho, rtol=2e-5)
            checked.append((step, since_build, int((count > spec.MAX_NEIGHBOURS).sum())))
    assert len(checked) >= 20, checked
    assert builds < 240 / 3, builds
    assert max(c[1] for c in checked) >= 3, checked
    if max_neighbours:
        assert all(c[2] > len(x) / 2 for c in checked), checked  # (most lists overflowed)


@pytest.mark.parametrize("base", [SCENE, SCENE_3D, SCENE_NARROW, SCENE_CONTINUITY, SCENE_CONTINUITY_4DX,
                                  SCENE_CONTINUITY_3D],
                         ids=["2d", "3d", "3d_narrow", "2d_continuity", "2d_continuity_4dx", "3d_continuity"])
def test_reused_lists_give_the_states_of_lists_built_every_step(base):
    """The same pairs, summed in the build's order: in float64, 300 steps with lists reused end within 1e-9 m and
    1e-8 of the density of the run that sorts and builds every step (Vulkan: lavapipe builds float64 pipelines in
    a moment). With continuity density the walks sum each pair's rate of the density, which is state."""
    vulkan_or_skip()
    states, builds = {}, {}
    for skin in (0.0, base["physics"]["list_skin"]):
        with Simulation(scene_of(base, **{"physics.list_skin": skin, "physics.precision": "float64"}), "vulkan") as sim:
            sim.advance(300)
            builds[skin] = int(sim.backend.read_buffer("control")[CONTROL_BUILDS])
            states[skin] = sim.read()
    plain, reused = states[0.0], states[base["physics"]["list_skin"]]
    assert builds[0.0] == 0 and 3 <= builds[base["physics"]["list_skin"]] <= 100, builds
    assert np.abs(plain["particle_v"]).max() > 0.3  # the column is moving
    np.testing.assert_allclose(reused["particle_x"], plain["particle_x"], rtol=0, atol=1e-9)
    np.testing.assert_allclose(reused["particle_rho"], plain["particle_rho"], rtol=1e-8)


@pytest.mark.parametrize("base", [SCENE, SCENE_3D, SCENE_CONTINUITY], ids=["2d", "3d", "2d_continuity"])
def test_reused_lists_are_bitwise_the_same_on_both_backends(base):
    """numba and lavapipe build at the same steps (the request is an order-free flag) and walk the same lists:
    150 steps give the same bits and the same count of builds."""
    vulkan_or_skip()
    out = {}
    for backend in BACKENDS:
        with Simulation(scene_of(base), backend) as sim:
            sim.advance(150)
            out[backend] = sim.backend.read_buffer("control")[CONTROL_BUILDS], sim.read()
    assert out["numba"][0] == out["vulkan"][0] > 1
    for name in ("particle_x", "particle_v", "particle_rho", "particle_p"):
        assert np.array_equal(out["numba"][1][name], out["vulkan"][1][name]), name


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_run_resumed_from_a_checkpoint_reaches_the_same_bits(backend):
    """A read of the state asks for a build at the next step, in the run that reads and in a run restored from what
    it read, so the two step on alike."""
    backend_or_skip(backend)
    scene = scene_of()
    with Simulation(scene, backend) as sim:
        sim.advance(80)
        checkpoint = sim.checkpoint()
        sim.advance(70)
        expected = sim.read()
    with Simulation(scene, backend) as sim:
        sim.restore(checkpoint)
        sim.advance(70)
        resumed = sim.read()
    for name in ("particle_x", "particle_v", "particle_rho"):
        assert np.array_equal(resumed[name], expected[name]), name


def test_a_run_counts_its_builds(tmp_path, capsys):
    """`sphcore run` says how often the lists were built, and so does final.npz: more than at the start, fewer than
    every step (the snapshots every 50 steps each ask for one)."""
    scene_file = tmp_path / "skin.toml"
    scene_file.write_text('name = "skin"\n[physics]\nmodel = "graphics"\nequation_of_state = "tait"\nlist_skin = 0.2\n'
                          '[domain]\nbox_max = [0.6, 0.4]\n'
                          '[fluid]\nspacing = 0.01\nblocks = [{min = [0.0, 0.0], max = [0.2, 0.3]}]\nstiffness = 900.0\n'
                          'viscosity = 0.5\n[time]\ndt = 2e-4\nsteps = 200\noutput_every = 50\n')  # (SCENE's)
    assert main(["run", str(scene_file), "--out", str(tmp_path / "run")]) == 0
    builds = int(np.load(tmp_path / "run" / "final.npz")["list_builds"])
    assert 4 < builds < 100
    assert f"200 steps, neighbour lists built {builds} times" in capsys.readouterr().out


def test_numba_runs_the_sort_and_scan_at_builds_only_and_profiles_the_walk_apart():
    """On numba a step launches either the sort and the build's scan or the walk, as the device's flag says, and
    the profile counts each as often as it ran ("compute_density (walk)" apart from the build)."""
    profile = Profile()
    with Simulation(scene_of(), "numba", profile=profile) as sim:
        sim.step(120)
        builds = int(sim.backend.read_buffer("control")[CONTROL_BUILDS]) - 1  # (less the start's)
    assert 2 <= builds < 60, builds
    assert profile.calls["compute_density"] == profile.calls["count_cells"] == builds
    assert profile.calls["compute_density (walk)"] == 120 - builds
    assert profile.calls["compute_forces"] == profile.calls["integrate"] == 120


@pytest.mark.parametrize("changes, message", [
    ({"physics.list_skin": -0.1}, "physics.list_skin"),
    ({"physics.list_skin": 1.5}, "physics.list_skin"),
    ({"physics.list_skin": "0.2 h"}, "physics.list_skin"),
    ({"physics.pressure_solver": "dfsph"}, "physics.pressure_solver"),
    ({"physics.neighbour_search": "all_pairs"}, "physics.neighbour_search"),
    ({"domain.obstacles": [{"min": [0.3, 0.0], "max": [0.35, 0.1]}]}, "domain.obstacles"),
    ({"domain.box_max": [0.6, 0.045], "fluid.blocks": [{"min": [0.0, 0.0], "max": [0.2, 0.04]}]}, "axis 1"),
])
def test_bad_values_are_rejected_naming_the_key(changes, message):
    with pytest.raises(SceneError) as e:
        scene_of(**changes)
    assert message in str(e.value)
