// The neighbour lists (dfsph.glsl: written by compute_density's scan), walked (walk.glsl) by compute_forces and
// wall_pressure, by compute_density between builds of reused lists, and under DFSPH by dfsph_factor (which stores
// each entry's gradient), dfsph_residual and dfsph_velocity (which read them). Needs particle_x, neighbours, neighbour_chunks (the same buffer as uvec4) and neighbour_gradients
// declared by the shader that includes this file (after cells.glsl, kernels.glsl, pairs.glsl and dfsph.glsl).
// A walk goes through the slots from 0 in order, keeping the last chunk it loaded in `chunk`.
// Mirror: sphcore/sph/neighbour_list.py (same names, same statements).

// Entry `slot` of particle i's list as written (j | image << IMAGE_SHIFT): lists in chunks (LIST_CHUNKS) are read
// a chunk of 4 slots at a time, one 16-byte load at each fourth slot (dfsph.glsl: list_slot).
uint listed_word(uint i, uint slot, inout uvec4 chunk) {
    if (LIST_BY_PARTICLE || !LIST_CHUNKS) return neighbours[list_slot(i, slot)];
    if ((slot & 3u) == 0u) chunk = neighbour_chunks[chunk_index(i, slot)];
    return lane_of(chunk, slot & 3u);
}

// Entry `slot` of particle i's list: its neighbour j, or j's image across the walls and obstacle faces
// whose bits are set in `image` (`wall`: near_walls and near_obstacles at xi), with r = xi - x_k; returns r2,
// the squared distance to it.
real listed_distance(uint i, uint slot, inout uvec4 chunk, real3 xi, real3 wall, out uint j, out uint image,
                     out real3 r) {
    uint pair = listed_word(i, slot, chunk);
    j = pair & NEIGHBOUR_MASK;
    image = pair >> IMAGE_SHIFT;
    real3 xk = particle_x[j].xyz;
    if (image != 0u) xk = reflected(xk, wall, image);  // (most entries are particles: no selects for them)
    r = xi - xk;
    return r.x * r.x + r.y * r.y + r.z * r.z;
}

// The same, with rlen, the plain distance (`inward`: near_obstacles at xi); returns the direction from the entry
// to i (pairs.glsl).
real3 listed_pair(uint i, uint slot, inout uvec4 chunk, real3 xi, real3 wall, real3 inward, out uint j,
                  out uint image, out real3 r, out real r2, out real rlen) {
    r2 = listed_distance(i, slot, chunk, xi, wall, j, image, r);
    rlen = sqrt(r2);
    return pair_direction(r, rlen, i, j, image, inward);
}

// Entry `slot` of particle i's list under DFSPH: its neighbour j (`image`: the walls it is mirrored across);
// returns g = V grad_i W_ik. With GRADIENTS, as dfsph_factor stored it this step (neighbour_gradients, in the
// list's layout); else computed again as dfsph_factor computed it: the same bits without fused multiply-adds.
real3 listed_gradient(uint i, uint slot, inout uvec4 chunk, real3 xi, real3 wall, real3 inward, out uint j,
                      out uint image) {
    if (GRADIENTS) {
        uint pair = listed_word(i, slot, chunk);
        j = pair & NEIGHBOUR_MASK;
        image = pair >> IMAGE_SHIFT;
        return neighbour_gradients[list_slot(i, slot)].xyz;
    }
    real3 r;
    real r2;
    real rlen;
    real3 r_hat = listed_pair(i, slot, chunk, xi, wall, inward, j, image, r, r2, rlen);
    real g = real(P.pressure_coef) / real(P.rest_density) * pair_gradient(r2, rlen, image);
    return -(g * r_hat);
}
