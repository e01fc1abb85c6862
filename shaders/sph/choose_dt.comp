#version 460
// The step's dt and the simulated time, on the device, one invocation (in the plan with
// time.dt = "adaptive" or time.integrator = "verlet"). time_state[0] = (dt, the last step's dt,
// time hi, time lo): integrate.comp reads dt and the last step's, the host reads the time only when
// it writes output (no readback per step).
//   ADAPTIVE_DT: dt = min(P.dt, cfl_number h / (c + |v|max), cfl_number sqrt(h / |a|max)) over the
//   partials of reduce_dt.comp (Monaghan 1992's CFL and force bounds; P.dt is the viscous bound
//   0.125 h^2 / nu, Morris et al. 1997), c^2 = k (Tait: 7 B / rho_0), cfl_number = 0.25 time.dt_fraction.
//   Else dt = P.dt (Verlet needs the last step's dt: 0 at the first step).
// Mirror: sphcore/sph/choose_dt.py (same names, same statement order, same step labels).
#extension GL_GOOGLE_include_directive : require
layout(local_size_x_id = 0) in;
#include "params.glsl"
#include "constants.glsl"
#include "real.glsl"

layout(std430, binding = 20) buffer TimeState { vec4 time_state[]; };
layout(std430, binding = 21) readonly buffer DtPartial { real dt_partial[]; };  // (|v|^2, |a|^2) per group

void main() {
    // [1] one invocation
    if (gl_GlobalInvocationID.x != 0u) return;
    float dt = P.dt;
    if (ADAPTIVE_DT) {
        // [2] the largest |v|^2 and |a|^2 over reduce_dt's partials, one per work group of its dispatch
        uint groups = (P.n + gl_WorkGroupSize.x - 1u) / gl_WorkGroupSize.x;
        real v2 = real(0.0);
        real a2 = real(0.0);
        for (uint g = 0u; g < groups; ++g) {
            v2 = max(v2, dt_partial[2u * g]);
            a2 = max(a2, dt_partial[2u * g + 1u]);
        }
        // [3] the bounds: CFL on c + |v|max, force on |a|max (none where nothing accelerates), P.dt
        real c = sqrt(TAIT ? real(7.0) * P.stiffness / P.rest_density : real(P.stiffness));
        real bound = P.cfl_number * P.h / (c + sqrt(v2));
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
