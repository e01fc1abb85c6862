#version 460
// Density and pressure, one invocation per particle. Neighbours from the grid (GRID) or all
// pairs; wall and obstacle-face images (WALLS, OBSTACLES); linear or Tait equation of state (TAIT).
// The kernel is kernels.glsl's (KERNEL). Summation density: rho_i = sum_j m W_ij. Continuity
// density (CONTINUITY): rho_i is state, integrated by integrate.comp from the d rho/dt written here
// (particle_drho), with density diffusion (DENSITY_DIFFUSION, density_diffusion.glsl). The bodies' wall particles
// (BODIES) count as fluid of their density in the sum, as fixed particles in the rate; wall_pressure.comp then
// sets their own density and pressure. With neighbour
// lists (MAX_NEIGHBOURS > 0: DFSPH, and the state equation where they fit, Scene.spec_for) the scan also writes the
// particle's list (dfsph.glsl), which compute_forces walks, and under DFSPH dfsph_factor and the solves. Lists
// reused between builds (LIST_SKIN, cells.glsl: list_reach): a build (D.level 0) lists out to list_reach and keeps
// where each particle was (scratch_x); a step between builds (D.level 1) walks the lists instead of the cells.
// The scan is walk.glsl's written out, not called through its hooks (walk.glsl says why: 6 % of this stage).
// Mirror: sphcore/sph/compute_density.py (same names, same statement order, same step labels).
#extension GL_GOOGLE_include_directive : require
layout(local_size_x_id = 0) in;
#include "params.glsl"
#include "constants.glsl"
#include "real.glsl"
#include "cells.glsl"
#include "kernels.glsl"
#include "pairs.glsl"
#include "density_diffusion.glsl"
#include "equation_of_state.glsl"
#include "dfsph.glsl"
#include "summed.glsl"

layout(std430, binding = 16) readonly buffer ObstacleBox { vec4 obstacle_box[]; };
#include "obstacles.glsl"

layout(std430, binding = 0) readonly buffer ParticleX { real4 particle_x[]; };
layout(std430, binding = 1) readonly buffer ParticleV { real4 particle_v[]; };
layout(std430, binding = 3) buffer ParticleRho { real particle_rho[]; };  // written (summation) or read (continuity)
layout(std430, binding = 4) writeonly buffer ParticleP { real particle_p[]; };
layout(std430, binding = 8) readonly buffer CellPyramid { uint cell_pyramid[]; };
layout(std430, binding = 9) readonly buffer CellStart { uint cell_start[]; };
layout(std430, binding = 11) buffer ScratchX { real4 scratch_x[]; };  // LIST_SKIN: x at the list's build
layout(std430, binding = 5) readonly buffer ParticleId { uint particle_id[]; };
layout(std430, binding = 15) writeonly buffer ParticleNeighbours { uvec2 particle_neighbours[]; };
layout(std430, binding = 17) writeonly buffer ParticleDrho { real particle_drho[]; };
layout(std430, binding = 29) buffer Neighbours { uint neighbours[]; };
layout(std430, binding = 29) buffer NeighbourChunks { uvec4 neighbour_chunks[]; };  // (the same, by chunks: dfsph.glsl)
layout(std430, binding = 24) buffer Control { uint control[]; };  // LIST_SKIN: CONTROL_BUILDS
layout(std430, binding = 30) buffer NeighbourCount { uint neighbour_count[]; };
layout(std430, binding = 31) readonly buffer NeighbourGradients { real4 neighbour_gradients[]; };  // (unread: named by
                                                                                           // neighbour_list.glsl)
#include "neighbour_list.glsl"

// Order-independent fingerprint of a neighbour (id, image): a 32-bit mix summed over the set.
uint neighbour_hash(uint id, uint image) {
    uint h = (id * 8u + image) * 0x9E3779B1u;
    h ^= h >> 15;
    h *= 0x85EBCA77u;
    h ^= h >> 13;
    return h;
}

// A scan with no branch on the distance (BRANCH_FREE_SCAN, where the list is written and the density summed):
// once the flow has lost its lattice a CPU mispredicts that branch, about one candidate in seven being a neighbour.
// Every candidate goes into the list's next slot, which only one within h keeps, self included; the kernel is
// then summed over the list in the scan's order and self taken out of it (listed_sum): the same bits as the scan
// with the branch. Before a cell range that could fill the list, it is summed, and the scan goes on with the branch.
const bool LIST_FIRST = BRANCH_FREE_SCAN && MAX_NEIGHBOURS > 0u && !CONTINUITY && !NEIGHBOUR_STATS && LIST_SKIN == 0u;
// A list in chunks (LIST_CHUNKS, dfsph.glsl: list_slot) is written a chunk of 4 entries at a time, gathered in
// `chunk`: one 16-byte store where the GPU paid for four scattered ones (a list-first scan writes entry by entry).
const bool CHUNKED = LIST_CHUNKS && !LIST_BY_PARTICLE && !LIST_FIRST;

// Adds kernel_w over the `count` entries of i's list (a list-first scan's, self among them) to sum_w in the
// list's order, and takes self out of the list: returns the others' count.
uint listed_sum(uint i, real3 xi, real3 wall, uint count, inout real sum_w) {
    uint self_seen = 0u;
    uvec4 chunk = uvec4(0u);
    for (uint slot = 0u; slot < count; ++slot) {
        uint j;
        uint image;
        real3 r;
        sum_w += kernel_w(listed_distance(i, slot, chunk, xi, wall, j, image, r));
        neighbours[list_slot(i, slot - self_seen)] = j | (image << IMAGE_SHIFT);
        self_seen |= uint(j == i && image == 0u);
    }
    return count - self_seen;
}

// Continuity density: one other particle's or image's terms of d rho_i/dt, at r = xi - x_k within h
// (k: j's image across the walls of `image`'s bits), added to sum_div and sum_diffusion; the scan's and a reused
// list's walk's. A wall particle of the bodies (BODIES) is fixed: its velocity here is 0 (wall_pressure.comp's is
// the viscous term's). It takes part in the diffusion with the density of its extrapolated pressure, as an image
// does with its particle's: left out, the fluid at a wall lost density to the kernel's missing half and sank through
// it (Molteni's term: a 3D tank at rest leaked at 1.5 s, docs/models/walls.md).
void add_rate(uint i, uint j, uint image, real3 r, real r2, real3 xi, real3 vi, real rhoi, real3 inward,
              inout real sum_div, inout real sum_diffusion) {
    // the direction r_hat from the neighbour to i (pairs.glsl); an image's velocity is mirrored on its
    // flipped axes
    real rlen = sqrt(r2);
    real3 r_hat = pair_direction(r, rlen, i, j, image, inward);
    bool wall_j = BODIES && particle_id[j] >= P.fluid_count;
    real3 vj = wall_j ? real3(0.0) : particle_v[j].xyz;
    real vk_x = (image & 1u) != 0u ? -vj.x : vj.x;
    real vk_y = (image & 2u) != 0u ? -vj.y : vj.y;
    real vk_z = (image & 4u) != 0u ? -vj.z : vj.z;
    real v_r = (vi.x - vk_x) * r_hat.x + (vi.y - vk_y) * r_hat.y + (vi.z - vk_z) * r_hat.z;
    // d rho_i/dt = sum_j m (v_i - v_j) . grad_i W_ij = -pressure_coef sum_j kernel_gradient v_ij . r_hat
    sum_div += pair_gradient(r2, rlen, image) * v_r;
    // density diffusion D_i (density_diffusion.glsl) at the pair's (or image's) distance; an image carries
    // its particle's density, so its hydrostatic difference is its particle's
    if (DENSITY_DIFFUSION > 0u)
        sum_diffusion += diffusion_term(rhoi, particle_rho[j], particle_x[j].xyz - xi, r2, rlen);
}

void main() {
    // [1] one invocation per particle; the grid is rounded up to whole work groups. On a rank of sphcore.parallel
    //     the rows whose density a step reads alone (summed.glsl; the others keep what they held)
    uint i = gl_GlobalInvocationID.x;
    if (i >= P.n) return;
    if (LIST_SKIN > 0u && D.level != 1u && i == 0u) control[CONTROL_BUILDS] += 1u;
    if (!summed_row(particle_x[i][DIM - 1u])) return;
    // [2] own position; with continuity density also the velocity and the density (state)
    real3 xi = particle_x[i].xyz;
    real3 vi = real3(0.0);
    real rhoi = real(0.0);
    if (CONTINUITY) {
        vi = particle_v[i].xyz;
        rhoi = particle_rho[i];
    }
    // [3] wall images: within h of a wall, particle i also sees every particle mirrored across
    //     it (ghost fluid: free-slip boundary of Takeda et al. 1994). Bit a of `mirrored` says
    //     that the wall nearer to xi on axis a is within h; an obstacle's face in front of xi
    //     takes the place of its axis's wall where nearer (obstacles.glsl). Reused lists (LIST_SKIN): the walls
    //     within list_reach of where i was at the list's build (this step's position at a build, D.level 0)
    bool walk = LIST_SKIN > 0u && D.level == 1u;
    real3 x_built = walk ? scratch_x[i].xyz : xi;
    real3 wall;
    real3 inward;
    uint mirrored = mirror_planes(x_built, xi, wall, inward);  // (obstacles.glsl)
    // [4] sum kernel_w over every particle and image within h, self included (with
    //     NEIGHBOUR_STATS, also count them and sum a hash of each (id, image): the set's fingerprint). Image
    //     `image` mirrors the axes of its bits; the image of j is within h of xi exactly when j
    //     is within h of xi's own image xm, so the cells searched are those around xm.
    //     Continuity: sum the velocity divergence and the diffusion term over the others instead.
    //     Lists: each of the others into the list, in the scan's order, j | image << IMAGE_SHIFT
    //     (LIST_FIRST: every candidate first, summed from the list after; CHUNKED: by chunks of 4). A build of
    //     reused lists lists the others within list_reach
    real sum_w = real(0.0);
    real sum_div = real(0.0);
    real sum_diffusion = real(0.0);
    uint found = 0u;
    uint fingerprint = 0u;
    uint count = 0u;
    bool listing = LIST_FIRST;
    uvec4 chunk = uvec4(0u);
    real reach2 = list_reach() * list_reach();
    bool scanning = true;
    if (walk) {  // [5] a reused list: self, and the listed particles and images now within h, in the list's order
                 //     (continuity: the others' rates, add_rate); a list that overflowed at its build scans the
                 //     cells of the build around x_built instead
        count = neighbour_count[i];
        scanning = count > MAX_NEIGHBOURS;
    }
    if (!scanning) {
        sum_w = kernel_w(real(0.0));
        for (uint slot = 0u; slot < count; ++slot) {
            uint j;
            uint image;
            real3 r;
            real r2 = listed_distance(i, slot, chunk, xi, wall, j, image, r);
            if (r2 >= P.h2) continue;
            if (!CONTINUITY) sum_w += kernel_w(r2);
            if (CONTINUITY) add_rate(i, j, image, r, r2, xi, vi, rhoi, inward, sum_div, sum_diffusion);
        }
    }
    for (uint image = 0u; image < 8u; ++image) {
        if (!scanning || (image & ~mirrored) != 0u) continue;
        real3 xm = reflected(x_built, wall, image);
        ivec3 base = cell_of(xm);
        // [6] the 3^dim cells around xm, as ranges of sorted particles (cells.glsl: range_cells; written out, not
        //     cell_ranges.glsl's cell_range: through it the step ran 0.8 % slower on an H200)
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
            if (listing && count + (end - start) > MAX_NEIGHBOURS) {  // the list may fill: summed now, and the
                count = listed_sum(i, xi, wall, count, sum_w);          // rest scanned with the branch
                listing = false;
            }
            for (uint j = start; j < end; ++j) {
                real3 xk = particle_x[j].xyz;
                if (image != 0u) xk = reflected(xk, wall, image);
                if (OBSTACLES > 0u && image != 0u && !solid(xk)) continue;  // (obstacles.glsl)
                real3 r = xi - xk;
                real r2 = r.x * r.x + r.y * r.y + r.z * r.z;
                if (listing) {  // (list first: every candidate into the next slot, kept by one within h)
                    neighbours[list_slot(i, count)] = j | (image << IMAGE_SHIFT);
                    count += uint(r2 < P.h2);
                    continue;
                }
                bool within = r2 < P.h2;
                if (within || (LIST_SKIN > 0u && !walk && r2 < reach2)) {
                    if (!CONTINUITY && within) sum_w += kernel_w(r2);
                    if (NEIGHBOUR_STATS && within) {
                        found += 1u;
                        fingerprint += neighbour_hash(particle_id[j], image);
                    }
                    if (MAX_NEIGHBOURS > 0u && !walk && (j != i || image != 0u)) {
                        if (count < MAX_NEIGHBOURS) {
                            uint pair = j | (image << IMAGE_SHIFT);
                            if (CHUNKED) {
                                chunk[count & 3u] = pair;
                                if ((count & 3u) == 3u) neighbour_chunks[chunk_index(i, count)] = chunk;
                            } else {
                                neighbours[list_slot(i, count)] = pair;
                            }
                        }
                        count += 1u;
                    }
                }
                // [7] continuity: the rates of the others within h (add_rate: the velocity divergence, d rho_i/dt,
                //     and the density diffusion D_i)
                if (CONTINUITY && within && (j != i || image != 0u)) add_rate(i, j, image, r, r2, xi, vi, rhoi, inward,
                                                                             sum_div, sum_diffusion);
            }
        }
    }
    if (listing) count = listed_sum(i, xi, wall, count, sum_w);
    uint kept = min(count, MAX_NEIGHBOURS);
    if (CHUNKED && !walk && (kept & 3u) != 0u) neighbour_chunks[chunk_index(i, kept)] = chunk;  // (the last chunk's rest: unread)
    // [8] summation: rho_i = m sum_j W(r_ij, h); continuity: the state's rho_i, and its rate (which
    //     integrate_density, the next stage, adds: it needs every neighbour's density unchanged here)
    real rho = P.density_coef * sum_w;
    real drho = real(0.0);
    if (CONTINUITY) {
        rho = rhoi;
        drho = -P.pressure_coef * sum_div;
        if (DENSITY_DIFFUSION > 0u) drho += P.diffusion_coef * sum_diffusion;
    }
    // [9] equation of state (equation_of_state.glsl: linear or Tait; clamped at 0 with summation
    //     density only)
    real p = equation_of_state(rho);
    // [10] store
    if (!CONTINUITY) particle_rho[i] = rho;
    particle_p[i] = p;
    if (CONTINUITY) particle_drho[i] = drho;
    if (NEIGHBOUR_STATS) particle_neighbours[i] = uvec2(found, fingerprint);
    if (MAX_NEIGHBOURS > 0u && !walk) neighbour_count[i] = count;  // (longer than its slots: compute_forces
                                                                         // scans, DFSPH stops)
    if (LIST_SKIN > 0u && !walk) scratch_x[i] = particle_x[i];  // (where the list was built: integrate, the walks)
}
