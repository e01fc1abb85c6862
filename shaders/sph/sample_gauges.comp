#version 460
// The scene's gauges ([[gauges]], sphcore/gauges.py), one invocation per gauge, in the plan after compute_forces
// and before choose_dt: positions, velocities, densities, pressures and accelerations are then all of the step's
// start, and so is the time in time_state (hi + lo: this step's choose_dt has not added its dt yet). A gauge takes
// a sample at the first step whose time is at or past its next multiple of its interval (within runner.ROUNDING,
// as the snapshots), and nothing else: a step with no sample due costs one comparison a gauge.
//   pressure, velocity, density at a point x: the Shepard-normalised SPH interpolation over the fluid within h,
//     q(x) = sum_j q_j V_j W(x - x_j) / sum_j V_j W(x - x_j), V_j = m / rho_j (DualSPHysics' MeasureTool and
//     GaugeVel; Shepard 1968); mirror images across the walls and the bodies' wall particles are left out (the normalisation makes up for the
//     missing half of the support at a wall). No fluid within h: 0.
//   height: the free-surface elevation above the foot x on the vertical line (DualSPHysics' GaugeSwl; the axis
//     gravity points along, gauge_state's second word, upward toward the box's top): the kernel-weighted mass sum m sum_j W is evaluated every `step` (gauge_table's second row, dx / 2)
//     from the foot to the box's top, and the surface is the highest point where it falls below rest_density / 2,
//     interpolated linearly between the two points around it; 0 where no point reaches it.
//   force, moment on a body: F = m sum a_j over the body's particles (ids [first, first + count), after
//     compute_forces particle_a holds the fluid's force on them per unit mass), M = sum (x_j - about) x (m a_j);
//     one invocation sums each cell layer's rows in the buffers' order, then the layers' sums in layer order (the
//     same on both backends): the same bits every run.
// A sample is the row (time, value x, y, z) at slot `taken` mod GAUGE_SLOTS of the gauge's ring in gauge_samples,
// which the host reads before it can fill (sphcore.gauges.GaugeReader). Layouts: sphcore/plan.py (BUFFERS).
// On a rank of sphcore.parallel (P.owned_end > 0) a gauge samples what lies in the rank's slab (in_slab): a point
// there, and of a height's line the points there and each one's point below (the halo reaches that far:
// decomposition.halo_width), the surface found only between a point there and the one below. Its value y says
// whether it found one (height); a rank that sampled nothing writes the time -1. sphcore.gauges.merged takes each
// sample from the ranks' rows: the bits of one rank's. Of a force or moment a rank writes each of its slab's layers'
// sums (the others' 0) in gauge_layers, a ring of LAYER_SLOTS samples a gauge (rows of P.grid_dim[DIM - 1] layers),
// which merged adds over the ranks and then along the layers: the bits of one rank's, wherever the cuts fall.
// Mirror: sphcore/sph/sample_gauges.py (same names, same statement order, same step labels).
#extension GL_GOOGLE_include_directive : require
layout(local_size_x_id = 0) in;
#include "params.glsl"
#include "constants.glsl"
#include "real.glsl"
#include "cells.glsl"
#include "kernels.glsl"

layout(std430, binding = 0) readonly buffer ParticleX { real4 particle_x[]; };
layout(std430, binding = 1) readonly buffer ParticleV { real4 particle_v[]; };
layout(std430, binding = 2) readonly buffer ParticleA { real4 particle_a[]; };
layout(std430, binding = 3) readonly buffer ParticleRho { real particle_rho[]; };
layout(std430, binding = 4) readonly buffer ParticleP { real particle_p[]; };
layout(std430, binding = 5) readonly buffer ParticleId { uint particle_id[]; };
layout(std430, binding = 8) readonly buffer CellPyramid { uint cell_pyramid[]; };
layout(std430, binding = 9) readonly buffer CellStart { uint cell_start[]; };
layout(std430, binding = 20) readonly buffer TimeState { vec4 time_state[]; };
layout(std430, binding = 32) readonly buffer GaugeTable { vec4 gauge_table[]; };
layout(std430, binding = 33) buffer GaugeState { uvec4 gauge_state[]; };
layout(std430, binding = 34) writeonly buffer GaugeSamples { real4 gauge_samples[]; };
layout(std430, binding = 38) readonly buffer LayerStart { uint layer_start[]; };
layout(std430, binding = 39) writeonly buffer GaugeLayers { real4 gauge_layers[]; };
#include "cell_ranges.glsl"

const uint PRESSURE = 0u;  // sphcore.gauges.QUANTITIES
const uint VELOCITY = 1u;
const uint DENSITY = 2u;
const uint HEIGHT = 3u;
const uint FORCE = 4u;
const uint MOMENT = 5u;
const uint LAYER_SLOTS = 16u;  // sphcore.gauges.LAYER_SLOTS: samples a gauge's ring of layer sums holds

// Whether time t is at or past `target`, within 1e-6 of it (runner.reached: n dt in float32 falls short of a decimal
// time by its rounding); `precise`: no contraction, the same bits as the mirror.
bool reached(float t, float target) {
    precise float least = target - 1e-6 * target;
    return t >= least;
}

// Sums over the fluid within h of point x: (sum V W, sum V W p, sum V W rho, sum W) and sum V W v, V W in units of
// m times W's coefficient (which the normalisation cancels); the bodies' wall particles left out.
real4 point_sums(real3 x, out real3 sum_v) {
    real4 sums = real4(0.0);
    sum_v = real3(0.0);
    ivec3 base = cell_of(x);
    for (uint k = 0u; k < range_count(); ++k) {
        uint start;
        uint end;
        if (!cell_range(base, k, start, end)) continue;  // (cell_ranges.glsl)
        for (uint j = start; j < end; ++j) {
            real3 r = x - particle_x[j].xyz;
            real r2 = r.x * r.x + r.y * r.y + r.z * r.z;
            if (r2 >= P.h2 || (BODIES && particle_id[j] >= P.fluid_count)) continue;
            real w = kernel_w(r2);
            real vw = w / particle_rho[j];
            sums += real4(vw, vw * particle_p[j], vw * particle_rho[j], w);
            sum_v += vw * particle_v[j].xyz;
        }
    }
    return sums;
}

// Whether point x lies in this rank's slab: the layer of its cell along the slab axis (the slowest: cells.glsl),
// clamped into the grid as sphcore.decomposition.layers_of, among the cells owned_first .. owned_end - 1; every
// point where the rank owns every particle (owned_end 0).
bool in_slab(real3 x) {
    if (P.owned_end == 0u) return true;
    uint axis = DIM - 1u;
    int layer = clamp(cell_of(x)[axis], 0, int(P.grid_dim[axis]) - 1);
    uint first = uint(layer) * (P.cell_total / P.grid_dim[axis]);
    return first >= P.owned_first && first < P.owned_end;
}

// The free surface's elevation above foot x on the vertical line, along axis `up` (0 where the mass sum never
// reaches rho_0 / 2), of the points in the slab and the one below each (in_slab); `seen`: 0 where the slab holds
// no point of the line, 1 where the surface is not found there, 2 where it is.
real surface_height(real3 x, real step, uint up, out uint seen) {
    real x_up = x[up];
    real half_rest = real(0.5) * real(P.rest_density);
    real top = real(P.box_max[up]);
    real height = real(0.0);
    real before = real(0.0);
    real level = x_up;
    seen = 0u;
    for (uint k = 0u; level <= top; ++k) {
        real3 at = x;
        at[up] = level;
        real next = x_up + real(k + 1u) * step;
        real3 above = x;
        above[up] = next;
        bool mine = in_slab(at);
        if (mine || (next <= top && in_slab(above))) {
            real3 sum_v;
            real mass = real(P.density_coef) * point_sums(at, sum_v).w;
            // a fall below half the rest density between the last point and this one: the surface (the highest)
            if (mine && k > 0u && before >= half_rest && mass < half_rest) {
                height = level - step + step * (before - half_rest) / (before - mass) - x_up;
                seen = 2u;
            }
            if (mine) seen = max(seen, 1u);
            before = mass;
        }
        level = next;
    }
    return height;
}

void main() {
    // [1] one invocation per gauge
    uint g = gl_GlobalInvocationID.x;
    if (g >= uint(gauge_state.length()) / 2u) return;
    uvec4 kind = gauge_state[2u * g];
    uvec4 progress = gauge_state[2u * g + 1u];
    if (kind.w == 0u) return;  // (no gauge: a state without [[gauges]])
    // [2] due? the time at the step's start against the next multiple of the interval (runner.reached)
    float t = time_state[0].z + time_state[0].w;
    float interval = gauge_table[2u * g].w;
    if (!reached(t, float(progress.x) * interval)) return;
    // [3] the sample
    real3 x = real3(gauge_table[2u * g].xyz);
    real3 aux = real3(gauge_table[2u * g + 1u].xyz);
    real4 value = real4(0.0);
    bool sampled = kind.x >= FORCE || in_slab(x);  // (a height's: as its line finds)
    if (kind.x <= DENSITY && sampled) {
        real3 sum_v;
        real4 sums = point_sums(x, sum_v);
        if (sums.x > real(0.0)) {
            if (kind.x == PRESSURE) value.x = sums.y / sums.x;
            if (kind.x == VELOCITY) value.xyz = sum_v / sums.x;
            if (kind.x == DENSITY) value.x = sums.z / sums.x;
        }
    }
    if (kind.x == HEIGHT) {
        uint seen;
        value.x = surface_height(x, aux.x, kind.y, seen);
        value.y = real(seen == 2u);
        sampled = seen > 0u;
    }
    if (kind.x >= FORCE) {
        // a sum over each cell layer's rows (layer_start; the whole buffer without a grid), the layers' sums added
        // in layer order; on a rank (owned_end > 0) each layer's sum also into the sample's row of gauge_layers,
        // those of its slab's layers and 0 for the others: sphcore.gauges.merged adds the ranks' rows (x + 0 is
        // x) and the layers as here, to one rank's bits whatever the cuts
        real3 force = real3(0.0);
        precise real3 moment = real3(0.0);  // (precise: r x a not contracted to fused multiply-adds, as the mirror)
        uint layers = GRID ? P.grid_dim[DIM - 1u] : 1u;
        uint per_layer = P.cell_total / layers;
        uint row = (g * LAYER_SLOTS + progress.y % LAYER_SLOTS) * layers;
        for (uint layer = 0u; layer < layers; ++layer) {
            real3 layer_force = real3(0.0);
            precise real3 layer_moment = real3(0.0);
            bool mine = P.owned_end == 0u || (layer * per_layer >= P.owned_first && layer * per_layer < P.owned_end);
            uint first = GRID ? layer_start[layer] : 0u;
            uint end = layer + 1u < layers ? layer_start[layer + 1u] : P.n;
            for (uint i = first; mine && i < end; ++i) {
                if (particle_id[i] - kind.y >= kind.z) continue;  // (not the body's: unsigned, below first too)
                real3 a = particle_a[i].xyz;
                real3 r = particle_x[i].xyz - aux;
                layer_force += a;
                layer_moment += real3(r.y * a.z - r.z * a.y, r.z * a.x - r.x * a.z, r.x * a.y - r.y * a.x);
            }
            force += layer_force;
            moment += layer_moment;
            if (P.owned_end > 0u) gauge_layers[row + layer] = real4(kind.x == FORCE ? layer_force : layer_moment, 0.0);
        }
        real mass = real(gauge_table[2u * g + 1u].w);
        value.xyz = mass * (kind.x == FORCE ? force : moment);
    }
    // [4] store: the row at the ring's next slot, the count, and the next multiple past t
    real time = sampled ? real(time_state[0].z) + real(time_state[0].w) : real(-1.0);
    gauge_samples[g * kind.w + progress.y % kind.w] = real4(time, value.xyz);
    uint next = max(progress.x + 1u, uint(t / interval));
    while (reached(t, float(next) * interval)) next += 1u;
    gauge_state[2u * g + 1u] = uvec4(next, progress.y + 1u, 0u, 0u);
}
