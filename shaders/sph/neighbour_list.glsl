// The neighbour lists (dfsph.glsl: written by compute_density's scan), walked by compute_forces, and under
// DFSPH by dfsph_factor, dfsph_residual and dfsph_velocity. Needs particle_x and dfsph_neighbours declared
// by the shader that includes this file (after cells.glsl, pairs.glsl and dfsph.glsl).
// Mirror: sphcore/sph/neighbour_list.py (same names, same statements).

// Entry `slot` of particle i's list: its neighbour j, or j's image across the walls and obstacle faces
// whose bits are set in `image` (`wall`, `inward`: near_walls and near_obstacles at xi), with r = xi - x_k,
// r2 and rlen, the squared and plain distance to it; returns the direction from it to i (pairs.glsl).
real3 listed_pair(uint i, uint slot, real3 xi, real3 wall, real3 inward, out uint j, out uint image,
                  out real3 r, out real r2, out real rlen) {
    uint pair = dfsph_neighbours[slot * P.n + i];
    j = pair & NEIGHBOUR_MASK;
    image = pair >> IMAGE_SHIFT;
    real3 xk = particle_x[j].xyz;
    if (image != 0u) xk = reflected(xk, wall, image);  // (most entries are particles: no selects for them)
    r = xi - xk;
    r2 = r.x * r.x + r.y * r.y + r.z * r.z;
    rlen = sqrt(r2);
    return pair_direction(r, rlen, i, j, image, inward);
}
