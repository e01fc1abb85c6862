#version 460
// Continuity density (physics.density = "continuity", in the plan only then): one invocation per
// particle, after compute_density has summed d rho/dt at the step's positions and velocities, before
// compute_forces reads the densities and pressures:
//     rho_n = rho_{n-1} + dt_{n-1} drho(x_n, v_n),   p_n = p(rho_n)   (equation_of_state.glsl)
// The density is advanced with the velocities that moved the particles over the last step, as the
// positions are (x_n = x_{n-1} + dt v_n): the pair (rho, v) is stepped like (x, v), kick then drift.
// Advanced with the old velocities instead (forward Euler, rho += dt drho(v_{n-1}) in integrate), the
// sound waves grow every step: a tank at rest blew up within 100 steps. dt_{n-1} is P.dt, or with
// ADAPTIVE_DT the last step's dt (time_state.x: this step's choose_dt has not run yet; 0 at the start).
// Mirror: sphcore/sph/integrate_density.py (same names, same statement order, same step labels).
#extension GL_GOOGLE_include_directive : require
layout(local_size_x_id = 0) in;
#include "params.glsl"
#include "constants.glsl"
#include "real.glsl"
#include "equation_of_state.glsl"

layout(std430, binding = 3) buffer ParticleRho { real particle_rho[]; };
layout(std430, binding = 4) writeonly buffer ParticleP { real particle_p[]; };
layout(std430, binding = 17) readonly buffer ParticleDrho { real particle_drho[]; };
layout(std430, binding = 20) readonly buffer TimeState { vec4 time_state[]; };

void main() {
    // [1] one invocation per particle; the grid is rounded up to whole work groups
    uint i = gl_GlobalInvocationID.x;
    if (i >= P.n) return;
    // [2] the last step's dt
    float dt = ADAPTIVE_DT ? time_state[0].x : P.dt;
    // [3] rho_n = rho_{n-1} + dt drho, and its pressure
    real rho = particle_rho[i] + dt * particle_drho[i];
    real p = equation_of_state(rho);
    // [4] store
    particle_rho[i] = rho;
    particle_p[i] = p;
}
