// A particle's step (integrators.glsl: symplectic Euler or the kick-drift-kick Verlet leapfrog), box walls and
// obstacles: what integrate.comp stores of row i, also what pick_rows.comp sends of the rows it picks before
// integrate has run (on a rank whose exchange overlaps the step's end: sphcore.parallel). Needs ParticleX,
// ParticleV, ParticleA, ParticleVh and ObstacleBox bound.
// Mirror: sphcore/sph/integrate_row.py (same names, same statement order, same step labels).

// Row i after a step of `dt` (the last step's `dt_prev`: Verlet) and, with shifting (SHIFTING), `shift`'s sums
// (shifting.glsl): its position `x`, the velocity the integrator stores `v` and the one that moved it `vh` (Verlet's
// half step's).
void integrated(uint i, float dt, float dt_prev, real4 shift, out real3 x, out real3 v, out real3 vh) {
    // [1] kick and drift (integrators.glsl): vh is the velocity that moves the particle over the step
    real3 a = particle_a[i].xyz;
    vh = drift_velocity(particle_v[i].xyz, particle_vh[i].xyz, a, dt, dt_prev);
    x = particle_x[i].xyz + dt * vh;
    if (SHIFTING > 0u) x += shift_of(shift, vh, dt);  // (shifting.glsl: Lind et al. 2012)
    // [2] walls: each axis is tested on its own (no else-if), so a particle past a corner is
    //     put back on every wall it crossed in the same step. Clamp the position; an outward
    //     normal speed is reversed and scaled by the restitution, an inward one is kept.
    if (WALLS) {
        if (x.x < P.box_min.x) { x.x = P.box_min.x; vh.x = max(vh.x, -P.restitution * vh.x); }
        if (x.x > P.box_max.x) { x.x = P.box_max.x; vh.x = min(vh.x, -P.restitution * vh.x); }
        if (x.y < P.box_min.y) { x.y = P.box_min.y; vh.y = max(vh.y, -P.restitution * vh.y); }
        if (x.y > P.box_max.y) { x.y = P.box_max.y; vh.y = min(vh.y, -P.restitution * vh.y); }
        if (DIM == 3u && x.z < P.box_min.z) { x.z = P.box_min.z; vh.z = max(vh.z, -P.restitution * vh.z); }
        if (DIM == 3u && x.z > P.box_max.z) { x.z = P.box_max.z; vh.z = min(vh.z, -P.restitution * vh.z); }
    }
    // [3] obstacles (shaders/sph/obstacles.glsl): a particle that ended the step inside a box is put
    //     back onto the box's face nearest to it, its normal speed there treated as at a wall. The
    //     images across the faces keep particles off them; this catches the rare one that got in.
    for (uint o = 0u; o < OBSTACLES; ++o) {
        real3 lo = real3(obstacle_box[2u * o].xyz);
        real3 hi = real3(obstacle_box[2u * o + 1u].xyz);
        real3 depth = min(x - lo, hi - x);  // > 0: inside the box on that axis, that far from a face
        if (depth.x <= real(0.0) || depth.y <= real(0.0) || (DIM == 3u && depth.z <= real(0.0))) continue;
        if (depth.x <= depth.y && (DIM == 2u || depth.x <= depth.z)) {
            bool lower = x.x - lo.x <= hi.x - x.x;
            x.x = lower ? lo.x : hi.x;
            vh.x = lower ? min(vh.x, -P.restitution * vh.x) : max(vh.x, -P.restitution * vh.x);
        } else if (DIM == 2u || depth.y <= depth.z) {
            bool lower = x.y - lo.y <= hi.y - x.y;
            x.y = lower ? lo.y : hi.y;
            vh.y = lower ? min(vh.y, -P.restitution * vh.y) : max(vh.y, -P.restitution * vh.y);
        } else {
            bool lower = x.z - lo.z <= hi.z - x.z;
            x.z = lower ? lo.z : hi.z;
            vh.z = lower ? min(vh.z, -P.restitution * vh.z) : max(vh.z, -P.restitution * vh.z);
        }
    }
    // [4] the velocity the integrator stores (integrators.glsl)
    v = stored_velocity(vh, a, dt);
}
