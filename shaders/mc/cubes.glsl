// Marching-cubes helpers shared by the classify, traverse and per-cube shaders.
// Mirror: sphcore/mc/cubes.py (same names, same statements).
//
// The volume holds dim.x dim.y dim.z samples, z fastest (numpy's C order of an array indexed
// [x, y, z]); cube c has sample cube_origin(c) as its corner 0 and corner k at offset
// (k & 1, k >> 1 & 1, k >> 2 & 1). Its case has bit k set where corner k is inside
// (value > isolevel); case_edges lists the edges its triangles' vertices lie on (tables.glsl).

// Index of sample s in the volume.
uint sample_index(uvec3 s) {
    return (s.x * P.dim.y + s.y) * P.dim.z + s.z;
}

// Sample coordinates of cube c's corner 0.
uvec3 cube_origin(uint c) {
    uint ny = P.dim.y - 1u;
    uint nz = P.dim.z - 1u;
    return uvec3(c / (ny * nz), c / nz % ny, c % nz);
}

// Index of the cube with corner 0 at sample s (cube_origin's inverse).
uint cube_index(uvec3 s) {
    return (s.x * (P.dim.y - 1u) + s.y) * (P.dim.z - 1u) + s.z;
}

// Offset of corner k from corner 0 of its cube.
uvec3 corner_offset(uint k) {
    return uvec3(k & 1u, (k >> 1) & 1u, (k >> 2) & 1u);
}

// Case of the cube with corner 0 at sample s: bit k set where corner k is inside.
uint classify(uvec3 s) {
    uint code = 0u;
    for (uint k = 0u; k < 8u; ++k) {
        if (volume[sample_index(s + corner_offset(k))] > P.isolevel) code |= 1u << k;
    }
    return code;
}

// The bits of corners 0-3 (a cube's face at its lowest z) of the cube with corner 0 at sample s:
// classify(s) is cube_face(s) | cube_face(s + (0, 0, 1)) << 4.
uint cube_face(uvec3 s) {
    uint i = sample_index(s);
    uint x = P.dim.y * P.dim.z;
    uint y = P.dim.z;
    uint face = 0u;
    if (volume[i] > P.isolevel) face |= 1u;
    if (volume[i + x] > P.isolevel) face |= 2u;
    if (volume[i + y] > P.isolevel) face |= 4u;
    if (volume[i + x + y] > P.isolevel) face |= 8u;
    return face;
}

// Gradient of the volume at sample s: central differences, one-sided on the volume's faces
// (FORWARD_NORMALS: forward differences, backward on the last sample), per axis over the spacing.
vec3 gradient(uvec3 s) {
    vec3 g;
    for (uint a = 0u; a < 3u; ++a) {
        uvec3 lo = s;
        uvec3 hi = s;
        if (FORWARD_NORMALS) {
            if (s[a] + 1u < P.dim[a]) hi[a] += 1u; else lo[a] -= 1u;
        } else {
            if (s[a] > 0u) lo[a] -= 1u;
            if (s[a] + 1u < P.dim[a]) hi[a] += 1u;
        }
        g[a] = (volume[sample_index(hi)] - volume[sample_index(lo)]) / (float(hi[a] - lo[a]) * P.spacing[a]);
    }
    return g;
}

// Write vertex k of cube c (case `code`) to output slot v: its position on the edge by linear
// interpolation (MIDPOINT: the edge's midpoint), its unit normal against the gradient (towards
// lower values, outwards of a bright object, as scikit-image's), and a key naming its edge,
// 4 (lower sample) + axis, or its sample, 4 sample + 3, where the value there equals the
// isolevel exactly: the host welds vertices with equal keys into one.
void emit_vertex(uint c, uint code, uint k, uint v) {
    uint e = case_edges[code * CASE_WIDTH + k];
    uint axis = EDGE_AXIS[e];
    uvec3 s = cube_origin(c);
    uvec3 a = s + corner_offset(EDGE_CORNERS[e].x);
    uvec3 b = s + corner_offset(EDGE_CORNERS[e].y);
    float va = volume[sample_index(a)];
    float vb = volume[sample_index(b)];
    float t = MIDPOINT ? 0.5 : (P.isolevel - va) / (vb - va);
    uint key = 4u * sample_index(a) + axis;
    if (!MIDPOINT && t == 0.0) key = 4u * sample_index(a) + 3u;
    if (!MIDPOINT && t == 1.0) key = 4u * sample_index(b) + 3u;
    vec3 x = vec3(a);
    x[axis] += t;
    vec3 g = gradient(a) * (1.0 - t) + gradient(b) * t;
    float g_norm = length(g);
    vertex_position[v] = vec4(P.origin + x * P.spacing, 0.0);
    vertex_normal[v] = vec4(g_norm > 0.0 ? -g / g_norm : vec3(0.0), 0.0);
    vertex_key[v] = key;
}
