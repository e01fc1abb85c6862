#version 460
// Density and pressure, one invocation per particle. Neighbours from the grid (GRID) or all
// pairs; wall and obstacle-face images (WALLS, OBSTACLES); linear or Tait equation of state (TAIT).
// Mirror: sphcore/sph/compute_density.py (same names, same statement order, same step labels).
#extension GL_GOOGLE_include_directive : require
layout(local_size_x_id = 0) in;
#include "params.glsl"
#include "constants.glsl"
#include "real.glsl"
#include "cells.glsl"

layout(std430, binding = 16) readonly buffer ObstacleBox { vec4 obstacle_box[]; };
#include "obstacles.glsl"

layout(std430, binding = 0) readonly buffer ParticleX { real4 particle_x[]; };
layout(std430, binding = 3) writeonly buffer ParticleRho { real particle_rho[]; };
layout(std430, binding = 4) writeonly buffer ParticleP { real particle_p[]; };
layout(std430, binding = 8) readonly buffer CellPyramid { uint cell_pyramid[]; };
layout(std430, binding = 9) readonly buffer CellStart { uint cell_start[]; };
layout(std430, binding = 5) readonly buffer ParticleId { uint particle_id[]; };
layout(std430, binding = 15) writeonly buffer ParticleNeighbours { uvec2 particle_neighbours[]; };

// Order-independent fingerprint of a neighbour (id, image): a 32-bit mix summed over the set.
uint neighbour_hash(uint id, uint image) {
    uint h = (id * 8u + image) * 0x9E3779B1u;
    h ^= h >> 15;
    h *= 0x85EBCA77u;
    h ^= h >> 13;
    return h;
}

void main() {
    // [1] one invocation per particle; the grid is rounded up to whole work groups
    uint i = gl_GlobalInvocationID.x;
    if (i >= P.n) return;
    // [2] own position
    real3 xi = particle_x[i].xyz;
    // [3] wall images: within h of a wall, particle i also sees every particle mirrored across
    //     it (ghost fluid: free-slip boundary of Takeda et al. 1994). Bit a of `mirrored` says
    //     that the wall nearer to xi on axis a is within h; an obstacle's face in front of xi
    //     takes the place of its axis's wall where nearer (obstacles.glsl)
    real3 wall;
    uint mirrored = near_walls(xi, wall);
    real3 inward;
    mirrored = near_obstacles(xi, mirrored, wall, inward);
    // [4] sum (h^2 - r^2)^3 over every particle and image within h, self included (with
    //     NEIGHBOUR_STATS, also count them and sum a hash of each (id, image): the set's fingerprint). Image
    //     `image` mirrors the axes of its bits; the image of j is within h of xi exactly when j
    //     is within h of xi's own image xm, so the cells searched are those around xm.
    real sum_w = real(0.0);
    uint found = 0u;
    uint fingerprint = 0u;
    for (uint image = 0u; image < 8u; ++image) {
        if ((image & ~mirrored) != 0u) continue;
        real3 xm = reflected(xi, wall, image);
        ivec3 base = cell_of(xm);
        // [5] the 3^dim cells around xm, as ranges of sorted particles (cells.glsl: range_cells)
        for (uint k = 0u; k < range_count(); ++k) {
            uint start = 0u;
            uint end = P.n;
            if (GRID) {
                int first;
                int last;
                if (!range_cells(base, k, first, last)) continue;
                start = cell_start[first];
                end = cell_start[last] + cell_pyramid[last];
            }
            for (uint j = start; j < end; ++j) {
                real3 xk = reflected(particle_x[j].xyz, wall, image);
                if (OBSTACLES > 0u && image != 0u && !solid(xk)) continue;  // (obstacles.glsl)
                real3 r = xi - xk;
                real r2 = r.x * r.x + r.y * r.y + r.z * r.z;
                if (r2 < P.h2) {
                    real q = P.h2 - r2;
                    sum_w += q * q * q;
                    if (NEIGHBOUR_STATS) {
                        found += 1u;
                        fingerprint += neighbour_hash(particle_id[j], image);
                    }
                }
            }
        }
    }
    // [6] rho_i = m sum_j W_poly6(r_ij, h)
    real rho = P.density_coef * sum_w;
    // [7] equation of state, clamped at 0 so that the free surface does not pull (tensile
    //     instability); attraction, where a scene wants it, comes from the cohesion term.
    //     linear: p = k (rho - rho_0) (seed 1); Tait: p = B ((rho / rho_0)^7 - 1) (Becker &
    //     Teschner 2007, seed 2), the power by multiplications
    real p = P.stiffness * (rho - P.rest_density);
    if (TAIT) {
        real ratio = rho / P.rest_density;
        real ratio2 = ratio * ratio;
        real ratio4 = ratio2 * ratio2;
        p = P.stiffness * (ratio4 * ratio2 * ratio - real(1.0));
    }
    p = max(p, real(0.0));
    // [8] store
    particle_rho[i] = rho;
    particle_p[i] = p;
    if (NEIGHBOUR_STATS) particle_neighbours[i] = uvec2(found, fingerprint);
}
