#version 460
// The fluid's colour field at every sample of the volume, through the particles' neighbour
// grid: c(x) = sum_j m / rho_j W_poly6(x - x_j, h), about 1 inside the fluid and 0 outside;
// its isosurface c = 1/2 is the fluid's surface. One invocation per sample. The particles
// must be sorted by cell (shaders/sph: count_cells .. apply_order) and their densities known.
// With walls (WALLS), the particles' mirror images across the walls count too, as in the density
// (shaders/sph/compute_density.comp), so the field stays about 1 up to a wall; and the field is
// 0 beyond the walls, so the surface closes there (sphcore/surface.py: sample_grid puts each wall
// halfway between two samples, where the isosurface of a field of 1 against 0 lies).
// Mirror: sphcore/mc/sample_field.py (same names, same statement order, same step labels).
#extension GL_GOOGLE_include_directive : require
layout(local_size_x_id = 0) in;
#include "params.glsl"
#include "../sph/constants.glsl"
#include "../sph/cells.glsl"

layout(std430, binding = 0) writeonly buffer Volume { float volume[]; };
layout(std430, binding = 7) readonly buffer ParticleX { vec4 particle_x[]; };
layout(std430, binding = 8) readonly buffer ParticleRho { float particle_rho[]; };
layout(std430, binding = 9) readonly buffer CellPyramid { uint cell_pyramid[]; };
layout(std430, binding = 10) readonly buffer CellStart { uint cell_start[]; };

void main() {
    // [1] one invocation per sample
    uint i = gl_GlobalInvocationID.x;
    if (i >= P.dim.x * P.dim.y * P.dim.z) return;
    // [2] the sample's position
    uvec3 s = uvec3(i / (P.dim.y * P.dim.z), i / P.dim.z % P.dim.y, i % P.dim.z);
    vec3 x = P.origin + vec3(s) * P.spacing;
    // [3] beyond a wall: outside the fluid, so the surface closes at the wall
    if (WALLS && (x.x < P.box_min.x || x.y < P.box_min.y || x.z < P.box_min.z || x.x > P.box_max.x
                  || x.y > P.box_max.y || x.z > P.box_max.z)) {
        volume[i] = 0.0;
        return;
    }
    // [4] wall images (cells.glsl: near_walls, reflected): within h of a wall, x also sees every
    //     particle mirrored across it; the image of j is within h of x exactly when j is within h of
    //     x's own image xm, so the cells searched are those around xm
    vec3 wall;
    uint mirrored = near_walls(x, wall);
    // [5] sum (h^2 - r^2)^3 / rho_j over the particles and images within h, from the cells around
    //     each image xm of x (cells.glsl: range_cells)
    float sum_w = 0.0;
    for (uint image = 0u; image < 8u; ++image) {
        if ((image & ~mirrored) != 0u) continue;
        vec3 xm = reflected(x, wall, image);
        ivec3 base = cell_of(xm);
        for (uint k = 0u; k < range_count(); ++k) {
            int first;
            int last;
            if (!range_cells(base, k, first, last)) continue;
            uint start = cell_start[first];
            uint end = cell_start[last] + cell_pyramid[last];
            for (uint j = start; j < end; ++j) {
                vec3 r = xm - particle_x[j].xyz;
                float r2 = r.x * r.x + r.y * r.y + r.z * r.z;
                if (r2 < P.h2) {
                    float q = P.h2 - r2;
                    sum_w += q * q * q / particle_rho[j];
                }
            }
        }
    }
    // [6] c = m W_poly6's coefficient times the sum
    volume[i] = P.density_coef * sum_w;
}
