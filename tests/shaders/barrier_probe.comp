#version 460
// A probe of the work-group emulation (sphcore/workgroups.py, STYLE.md): every barrier here changes the
// result if it is missing. Each invocation puts a value in shared memory; after a barrier it reads the value
// of the invocation mirrored across the group (lid -> L - 1 - lid: the first half reads values that a run of
// the invocations one after another would not have written yet); after a second barrier it overwrites its
// own slot (which the mirrored invocation must have read first); then a tree sum over the group, a barrier
// after each level, and invocation 0 writes the group's sum. Built with -DNO_BARRIER, barrier() is left out.
// Mirror: tests/test_workgroups.py (one loop over the local invocations per phase).
layout(local_size_x_id = 0) in;
layout(std430, binding = 0) readonly buffer In { float x[]; };
layout(std430, binding = 1) writeonly buffer Out { float y[]; };
layout(std430, binding = 2) writeonly buffer Sums { float sums[]; };

#ifdef NO_BARRIER
#define BARRIER()
#else
#define BARRIER() barrier()
#endif

shared float s[gl_WorkGroupSize.x];

void main() {
    uint lid = gl_LocalInvocationID.x;
    uint i = gl_GlobalInvocationID.x;
    // [1] own value
    s[lid] = 2.0 * x[i] + float(lid);
    BARRIER();
    // [2] with the mirrored invocation's
    float mine = 0.5 * s[lid] + s[gl_WorkGroupSize.x - 1u - lid];
    y[i] = mine;
    BARRIER();
    // [3] own slot overwritten, then the group's sum by halves
    s[lid] = mine;
    BARRIER();
    for (uint stride = gl_WorkGroupSize.x / 2u; stride > 0u; stride >>= 1) {
        if (lid < stride) s[lid] += s[lid + stride];
        BARRIER();
    }
    if (lid == 0u) sums[gl_WorkGroupID.x] = s[0];
}
