#version 460
// Acceleration from pressure (Monaghan 1992: pressure.glsl), viscosity (laminar, Mueller et al. 2003, or artificial,
// Monaghan 1992: viscosity.glsl; wall images' velocities: walls.glsl), surface tension by cohesion (Becker &
// Teschner 2007: cohesion.glsl) and gravity, one invocation per particle; with shifting (shifting.glsl) also the
// sums integrate shifts the particle by. The bodies' wall particles (BODIES, wall_pressure.comp: Adami et al. 2012)
// act on the fluid through the pressure term (and with NO_SLIP the viscous one), not on each other; for each of
// them this stage computes the fluid's force on it instead (per unit mass, without gravity: the gauges' force on
// a body). Each pair's terms are `pair`'s, called by the one neighbour walk (walk.glsl: the list or the scan; wall
// and obstacle images as in compute_density). Each optional term is compiled out by its specialization constant.
// Mirror: sphcore/sph/compute_forces.py (same names, same statement order, same step labels).
#extension GL_GOOGLE_include_directive : require
layout(local_size_x_id = 0) in;
#include "params.glsl"
#include "constants.glsl"
#include "real.glsl"
#include "cells.glsl"
#include "kernels.glsl"
#include "pairs.glsl"
#include "dfsph.glsl"

layout(std430, binding = 16) readonly buffer ObstacleBox { vec4 obstacle_box[]; };
#include "obstacles.glsl"
#include "walls.glsl"
#include "viscosity.glsl"
#include "pressure.glsl"
#include "cohesion.glsl"
#include "shifting.glsl"

layout(std430, binding = 0) readonly buffer ParticleX { real4 particle_x[]; };
layout(std430, binding = 1) readonly buffer ParticleV { real4 particle_v[]; };
layout(std430, binding = 2) writeonly buffer ParticleA { real4 particle_a[]; };
layout(std430, binding = 3) readonly buffer ParticleRho { real particle_rho[]; };
layout(std430, binding = 4) readonly buffer ParticleP { real particle_p[]; };
layout(std430, binding = 5) readonly buffer ParticleId { uint particle_id[]; };  // BODIES: a wall particle's id
layout(std430, binding = 8) readonly buffer CellPyramid { uint cell_pyramid[]; };
layout(std430, binding = 9) readonly buffer CellStart { uint cell_start[]; };
layout(std430, binding = 11) readonly buffer ScratchX { real4 scratch_x[]; };  // LIST_SKIN: x at the list's build
layout(std430, binding = 12) writeonly buffer ParticleShift { real4 particle_shift[]; };  // SHIFTING: scratch_v,
                                                                                              // read by integrate
layout(std430, binding = 24) buffer Control { uint control[]; };  // LIST_SKIN: CONTROL_REBUILD
layout(std430, binding = 29) readonly buffer Neighbours { uint neighbours[]; };
layout(std430, binding = 29) readonly buffer NeighbourChunks { uvec4 neighbour_chunks[]; };  // (the same, by chunks)
layout(std430, binding = 30) readonly buffer NeighbourCount { uint neighbour_count[]; };
layout(std430, binding = 44) readonly buffer BandRows { uvec2 band_rows[]; };  // a rank's two passes (D.level)
#include "band_rows.glsl"
layout(std430, binding = 31) readonly buffer NeighbourGradients { real4 neighbour_gradients[]; };  // (unread: named by
                                                                                           // neighbour_list.glsl)
#include "neighbour_list.glsl"

// i's state and sums, private to the invocation: set by main, read and summed by `pair` over the walk
bool wall_i;
real3 vi;
real rhoi;
real pi_rho2;
real3 f_pressure;
real3 f_viscosity;
real3 f_cohesion;
real4 f_shift;

// One pair's terms (walk.glsl hands over every other particle and image within h of i): pressure
// (pressure.glsl: Monaghan 1992's symmetric form; DFSPH: the solver's, dfsph.glsl), viscosity of the scene's
// model (viscosity.glsl: laminar, Mueller et al. 2003, or artificial, Monaghan 1992; an image's velocity is
// the wall model's, walls.glsl: free slip reverses its normal component, no slip all of it) and cohesion
// between real particles only (cohesion.glsl: Becker & Teschner 2007; the walls are not wetted); the shifting
// sums, images included (shifting.glsl: Lind et al. 2012). A wall particle and the fluid: the pressure term, the
// viscous one with NO_SLIP only (its velocity wall_pressure's), the shifting sums; two wall particles: nothing.
void pair(uint i, uint j, uint image, real3 r, real r2, real3 inward) {
    bool wall_j = BODIES && particle_id[j] >= P.fluid_count;
    if (wall_i && wall_j) return;
    real rhoj = particle_rho[j];
    real pj = particle_p[j];
    real rlen = sqrt(r2);
    real grad = pair_gradient(r2, rlen, image);  // kernels.glsl: m grad_i W_ij = -P.pressure_coef grad r_hat
    // the direction from the neighbour to i (pairs.glsl; where the two coincide: an image along its plane's
    // inward normal, two particles along x, antisymmetrically in (i, j))
    real3 r_hat = pair_direction(r, rlen, i, j, image, inward);
    if (!DFSPH) f_pressure += pressure_monaghan(pi_rho2, pj, rhoj, grad) * r_hat;
    if (VISCOSITY && (NO_SLIP || !(wall_i || wall_j))) {
        real3 vk = image_velocity(particle_v[j].xyz, image);
        f_viscosity += viscous_term(vi, vk, r, r2, rhoi, rhoj, grad, kernel_laplacian(r2, rlen), r_hat);
    }
    if (SURFACE_TENSION && image == 0u && !wall_j) f_cohesion += cohesion_becker(r2, r);
    if (SHIFTING > 0u) f_shift += shifting_lind(r2, rlen, rhoj, grad, r_hat);
}
#include "walk.glsl"

void main() {
    // [1] one invocation per particle; the grid is rounded up to whole work groups. On a rank of sphcore.parallel
    //     (P.owned_end > 0) the rows the sort gave its slab's cells alone: nothing reads a halo row's acceleration
    //     (the next exchange writes over the row). A rank whose exchange overlaps the step's end runs two passes:
    //     D.level 1 one invocation per row its pick reads (band_rows.glsl: an indirect dispatch of as many), which it
    //     sends before the second, D.level 2 the others; else (0) one takes every row
    uint i = gl_GlobalInvocationID.x;
    uint e;
    if (D.level == 1u && !band_row_at(gl_GlobalInvocationID.x, i, e)) return;
    if (i >= P.n) return;
    if (P.owned_end > 0u && (i < cell_start[P.owned_first]
                             || (P.owned_end < P.cell_total && i >= cell_start[P.owned_end]))) {
        if (LIST_SKIN > 0u && i == 0u) control[CONTROL_REBUILD] = 0u;
        return;
    }
    if (D.level == 2u && band_row(i)) return;
    // [2] own state (BODIES: whether i is a wall particle)
    wall_i = BODIES && particle_id[i] >= P.fluid_count;
    real3 xi = particle_x[i].xyz;
    vi = particle_v[i].xyz;
    rhoi = particle_rho[i];
    real pi = particle_p[i];
    pi_rho2 = pi / (rhoi * rhoi);
    // [3] sums over every other particle and every wall or obstacle image within h (walk.glsl: i's list, or the
    //     scan)
    f_pressure = real3(0.0);
    f_viscosity = real3(0.0);
    f_cohesion = real3(0.0);
    f_shift = real4(0.0);
    walk_neighbours(i, xi);
    // [4] a_i = f_pressure + viscous acceleration + cohesion + g (f_pressure is per unit mass; the
    //     laminar sum is divided by rho_i, viscosity.glsl); a wall particle: the fluid's terms only
    real3 a = f_pressure;
    if (VISCOSITY) a += viscous_acceleration(f_viscosity, rhoi);
    if (SURFACE_TENSION && !wall_i) a += P.cohesion_coef * f_cohesion;
    if (GRAVITY && !wall_i) a += P.gravity;
    // [5] store, with shifting its sums (grad C_i, div r_i) for integrate; reused lists: the next build is
    //     integrate's to ask for (every dispatch that reads the request has run: backends.plan)
    particle_a[i] = real4(a, 0.0);
    if (SHIFTING > 0u) particle_shift[i] = f_shift;
    if (LIST_SKIN > 0u && i == 0u) control[CONTROL_REBUILD] = 0u;
}
