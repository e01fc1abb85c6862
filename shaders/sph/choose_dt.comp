#version 460
// The step's dt and the simulated time, on the device, one work group (in the plan with
// time.dt = "adaptive" or time.integrator = "verlet"). time_state[0] = (dt, the last step's dt,
// time hi, time lo): integrate.comp reads dt and the last step's, the host reads the time only when
// it writes output (no readback per step).
//   ADAPTIVE_DT: dt = min(P.dt, cfl_number h / (c + |v|max), cfl_number sqrt(h / |a|max)) over the
//   partials of reduce_dt.comp (Monaghan 1992's CFL and force bounds; P.dt is the viscous bound
//   0.125 h^2 / nu, Morris et al. 1997), c^2 = k (Tait: 7 B / rho_0), cfl_number = 0.25 time.dt_fraction.
//   The group's invocations share the partials (every local_size-th each) and reduce their maxima in
//   shared memory as reduce_dt does: exact in any order. Else dt = P.dt (Verlet needs the last
//   step's dt: 0 at the first step). On a rank of sphcore.parallel D.level 1 runs first, after
//   reduce_dt: it writes the group's largest |v|^2 and |a|^2 as the first partial, which the host
//   reads (a buffer it maps), replaces by the largest over the ranks and level 0 then takes.
// Mirror: sphcore/sph/choose_dt.py (same names, same statement order, same step labels; one local
// loop per phase between barriers).
#extension GL_GOOGLE_include_directive : require
layout(local_size_x_id = 0) in;
#include "params.glsl"
#include "constants.glsl"
#include "real.glsl"

layout(std430, binding = 20) buffer TimeState { vec4 time_state[]; };
layout(std430, binding = 21) buffer DtPartial { real dt_partial[]; };  // (|v|^2, |a|^2) per group

shared real s_v2[gl_WorkGroupSize.x];
shared real s_a2[gl_WorkGroupSize.x];

void main() {
    // [1] the largest |v|^2 and |a|^2 of every local_size-th of reduce_dt's partials (one per work group
    //     of its dispatch), from this invocation's on; one work group is dispatched
    uint lid = gl_LocalInvocationID.x;
    uint groups = (P.n + gl_WorkGroupSize.x - 1u) / gl_WorkGroupSize.x;
    real v2 = real(0.0);
    real a2 = real(0.0);
    if (ADAPTIVE_DT) {
        for (uint g = lid; g < groups; g += gl_WorkGroupSize.x) {
            v2 = max(v2, dt_partial[2u * g]);
            a2 = max(a2, dt_partial[2u * g + 1u]);
        }
    }
    s_v2[lid] = v2;
    s_a2[lid] = a2;
    barrier();
    // [2] tree: at stride s, each invocation at a multiple of 2 s takes the larger of its own and the one s above
    for (uint stride = 1u; stride < gl_WorkGroupSize.x; stride *= 2u) {
        if (lid % (2u * stride) == 0u && lid + stride < gl_WorkGroupSize.x) {
            s_v2[lid] = max(s_v2[lid], s_v2[lid + stride]);
            s_a2[lid] = max(s_a2[lid], s_a2[lid + stride]);
        }
        barrier();
    }
    if (lid != 0u) return;
    // (D.level 1, a rank's: the largest as the first partial, where the host takes the largest over the ranks)
    if (D.level == 1u) {
        dt_partial[0] = s_v2[0];
        dt_partial[1] = s_a2[0];
        return;
    }
    float dt = P.dt;
    if (ADAPTIVE_DT) {
        // [3] the bounds: CFL on c + |v|max, force on |a|max (none where nothing accelerates), P.dt
        v2 = s_v2[0];
        a2 = s_a2[0];
        real c = sqrt(TAIT ? real(7.0) * P.stiffness / P.rest_density : real(P.stiffness));
        real bound = P.cfl_number * P.h / (c + sqrt(v2));
        // (DFSPH, incompressible: the CFL on the particle speed alone, cfl_number = time.cfl_number dx / h)
        if (DFSPH) bound = sqrt(v2) * real(P.dt) > P.cfl_number * P.h ? P.cfl_number * P.h / sqrt(v2) : real(P.dt);
        if (a2 > real(0.0)) bound = min(bound, P.cfl_number * sqrt(P.h / sqrt(a2)));
        dt = min(P.dt, float(bound));
    }
    // [4] the time, t += dt, summed in a compensated float32 pair (Kahan 1965): hi + lo is the sum of
    //     the float32 dts to within about float32's epsilon of t, however many steps; `precise` keeps
    //     a compiler from contracting or reordering it
    precise float y = dt + time_state[0].w;
    precise float t = time_state[0].z + y;
    precise float lo = y - (t - time_state[0].z);
    // [5] store: this step's dt, the last step's, the time
    time_state[0] = vec4(dt, time_state[0].x, t, lo);
}
