"""The health checks of a run's state (sphcore.simulation.Simulation.read runs them): finite values,
particles inside the box, the grid's counts, and an energy that does not grow. A failed check raises
SimulationError naming the step, the particle and the likely cause.
"""
import math

import numpy as np

from sphcore import geometry
from sphcore.errors import SimulationError
from sphcore.scene import stable_dt


def energy_terms(scene, state):
    """(kinetic + potential from box_min, internal energy of the equation of state) [J; 2D: J/m].
    Nothing in the physics adds energy (walls and viscosity only take it away), so a run
    whose energy grows is blowing up. Internal energy: the integral of p / rho^2 d rho, from
    the densities of the last step (computed from the positions before it) or of the start."""
    x, v = state["particle_x"].astype(np.float64), state["particle_v"].astype(np.float64)
    rho = state["particle_rho"].astype(np.float64)
    rho0, k = scene["fluid.rest_density"], scene["fluid.stiffness"]
    r = rho / rho0
    if scene["physics.density"] == "summation":
        r = np.maximum(r, 1.0)  # the pressure is clamped at 0 below rest density (not with continuity)
    if scene["physics.equation_of_state"] == "tait":
        internal = k / 7.0 * ((r ** 6 - 1.0) / 6.0 + 1.0 / r - 1.0)
    else:
        internal = k * (np.log(r) + 1.0 / r - 1.0)
    g = np.asarray(scene["forces.gravity"]) if scene["physics.gravity"] else np.zeros(scene.dim)
    potential = -(x - np.asarray(scene["domain.box_min"])) @ g
    return float(scene.mass * (0.5 * (v * v).sum(axis=1) + potential).sum()), float(scene.mass * internal.sum())


def check_grid(sim, status):
    """Raise SimulationError if the grid saw a particle outside its range, or lost count of one."""
    steps = f"between steps {sim.checked_step} and {sim.step_count}"
    if status[0]:
        where = ("outside the box" if sim.scene["domain.boundary"] == "walls"
                 else f"beyond the hashed range (+-2^24 cells of {sim.scene.h:g} m)")
        raise SimulationError(f"{steps}: {int(status[0])} particle position(s) were {where} or not finite "
                              f"(the first: particle {int(status[1])}); likely cause: a blow-up "
                              f"(dt = {sim.scene.dt:g} s, estimated bound {stable_dt(sim.scene)[0]:.3g} s)")
    if status[2]:
        raise SimulationError(f"{steps}: the neighbour grid counted a different number of particles than "
                              f"{sim.n} in {int(status[2])} steps (a counter overflow): please report this")


def check_state(sim, state, ids=None, world=None):
    """Raise SimulationError at the first particle with a non-finite value or outside the box, or where the
    energy grew (check_energy). `ids`: the particle ids of the rows of `state` (default: row i is particle i);
    `world`: check_energy's figures over every rank (a rank of sphcore.parallel checks its own particles)."""
    for name, values in state.items():
        bad = ~np.isfinite(values.reshape(len(values), -1)).all(axis=1)
        if bad.any():
            i = int(np.argmax(bad))
            dt_max, bound = stable_dt(sim.scene)
            dt = sim.scene.dt
            cause = (f"time.dt = {dt:g} s exceeds the {bound} bound {dt_max:.3g} s" if dt > dt_max else
                     f"time.dt = {dt:g} s is within the estimated bound {dt_max:.3g} s ({bound}); "
                     "look for stiffness or viscosity at the ends of their ranges")
            cause = sim.solver.blow_up_cause() or cause
            raise SimulationError(f"blow-up at step {sim.step_count} (t = {sim.time:.6g} s): {name} of "
                                  f"particle {particle(i, ids)} is {values[i]} ({int(bad.sum())} particles non-finite); "
                                  f"likely cause: {cause}")
    check_energy(sim, state, world)
    if sim.scene["domain.boundary"] == "open":
        return
    check_bodies(sim, state)
    x = state["particle_x"]
    # the walls as the shaders see them (float32): a particle clamped onto a wall sits exactly there
    lo = np.asarray(sim.scene["domain.box_min"], np.float32)
    hi = np.asarray(sim.scene["domain.box_max"], np.float32)
    outside = ((x < lo) | (x > hi)).any(axis=1)
    if outside.any():
        i = int(np.argmax(outside))
        raise SimulationError(f"step {sim.step_count}: particle {particle(i, ids)} at {x[i]} left the box {lo} .. {hi}")


def particle(i, ids):
    """The id of row i of a state whose rows' ids are `ids` (None: row i is particle i)."""
    return i if ids is None else int(ids[i])


def check_bodies(sim, state):
    """Raise SimulationError at the first fluid particle more than a spacing inside a body (the wall leaked): of
    those nearest a wall lattice point that wall particles surround (sphcore.geometry.buried), the signed distance
    to the body of the wall particle nearest each. (A particle a fraction of a spacing in, at an impact, is pushed
    back out by the wall's pressure.)"""
    scene, dx = sim.scene, sim.scene["fluid.spacing"]
    x = state["particle_x"]
    suspects = np.flatnonzero(geometry.buried(sim.buried, x, scene["domain.box_min"], scene["domain.box_max"], dx))
    if len(suspects) == 0:
        return
    walls = sim.walls["particle_x"]
    body = np.array([sim.walls["body"][np.argmin(((walls - x[i]) ** 2).sum(axis=1))] for i in suspects])
    for k in np.unique(body):
        depth = -geometry.signed_distance(scene.bodies[k], x[suspects[body == k]])
        if depth.max() > dx:
            i = int(suspects[body == k][np.argmax(depth)])
            raise SimulationError(f"step {sim.step_count} (t = {sim.time:.6g} s): fluid particle {i} at {x[i]} is "
                                  f"{depth.max() / dx:.1f} spacings inside {geometry.where(k, scene['bodies'][k])}: "
                                  "the wall leaked (docs/models/walls.md: Limits)")


def energy_figures(scene, state, ids=None):
    """check_energy's figures of `state`: (its energy [J; 2D: J/m], the largest speed [m/s], that particle's id
    and position); of no particle (0, -1, -1, None). `ids` as check_state's."""
    speed = np.sqrt((state["particle_v"].astype(np.float64) ** 2).sum(axis=1))
    if len(speed) == 0:
        return 0.0, -1.0, -1, None
    i = int(np.argmax(speed))
    return sum(energy_terms(scene, state)), float(speed[i]), particle(i, ids), state["particle_x"][i]


def check_energy(sim, state, world=None):
    """Raise SimulationError if the energy grew past its start by 10 % (plus, per particle, the
    potential energy of a fall of h / 4 and the kinetic energy of 1 % of the sound
    speed), or a particle outruns twice the sound speed plus the free-fall speed (an explosion).
    The free-fall speed: from the top of the fluid to the floor, and in an open domain, where
    nothing stops a fall, also |g| t. The message says which of the two failed, with its figures.
    `world`: energy_figures over every rank (sphcore.parallel), else those of `state`; a non-finite
    energy there is another rank's non-finite values, which that rank names."""
    scene = sim.scene
    if sim.energy_start is None or scene["physics.surface_tension"]:  # cohesion's energy is not counted
        return
    c = math.sqrt(scene["fluid.stiffness"])
    g = math.sqrt(sum(a * a for a in scene["forces.gravity"])) if scene["physics.gravity"] else 0.0
    allowed = (sim.energy_start + 0.1 * abs(sim.energy_start)
               + sim.fluid_count * scene.mass * (g * scene.h / 4 + 0.5 * (0.01 * c) ** 2))
    energy, top, i, x = energy_figures(scene, state) if world is None else world
    fall = scene.speed_estimate() + (g * sim.time if scene["domain.boundary"] == "open" else 0.0)
    limit = 2.0 * (c + fall)
    if energy <= allowed and top <= limit or world is not None and not math.isfinite(energy):
        return
    went = "rose" if energy > sim.energy_start else "fell"
    if energy > allowed:
        what = (f"the energy rose from {sim.energy_start:.4g} J to {energy:.4g} J, past the {allowed:.4g} J "
                f"allowed, and particle {i} moves at {top:.3g} m/s (sound speed {c:.3g} m/s)")
    else:
        what = (f"particle {i} moves at {top:.3g} m/s, past the {limit:.3g} m/s allowed (twice the sound "
                f"speed {c:.3g} m/s plus the free-fall speed {fall:.3g} m/s), while the energy {went} from "
                f"{sim.energy_start:.4g} J to {energy:.4g} J")
    dt_max, bound = stable_dt(scene, scene.speed_estimate())
    dt = scene.dt
    lo, hi = np.asarray(scene["domain.box_min"]), np.asarray(scene["domain.box_max"])
    gap = min((x - lo).min(), (hi - x).min())
    if dt > dt_max:
        cause = f"time.dt = {dt:g} s exceeds the {bound} bound {dt_max:.3g} s"
    elif not (scene["physics.viscosity"] and scene.shear_viscosity > 0):
        coefficient = "fluid.alpha" if scene["physics.viscosity_model"] == "artificial" else "fluid.viscosity"
        cause = f"no viscosity: nothing damps the particles' noise (raise {coefficient})"
    elif scene["domain.boundary"] == "walls" and gap < scene["fluid.spacing"] / 2:
        cause = (f"particle {i} is {gap:.3g} m from a wall, closer than half a spacing, where its mirror images "
                 "(the walls' ghost particles) push it; a particle that starts on a wall is pushed by images "
                 "that coincide with it: start the fluid at least fluid.spacing / 2 inside the box")
    elif energy > allowed:
        lower = "time.dt_fraction" if scene["time.dt"] == "auto" else "time.dt"
        cause = (f"dt = {dt:g} s is within the estimated {bound} bound {dt_max:.3g} s, yet the state gains "
                 f"energy: lower {lower} (a stiff fluid needs a fraction of the CFL bound)")
    else:
        cause = (f"one particle flung without the energy growing (dt = {dt:g} s is within the estimated {bound} "
                 f"bound {dt_max:.3g} s): a pair too close, or a force that is not the physics'; please report it")
    raise SimulationError(f"blow-up at step {sim.step_count} (t = {sim.time:.6g} s): {what}; "
                          f"likely cause: {cause}")
