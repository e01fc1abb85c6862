"""Launch a mirrored shader body the way Vulkan does: work groups of local invocations.

`launcher(main)` returns `launch(n_groups, local_size, *args)`, the numba counterpart of
`vkCmdDispatch(n_groups, 1, 1)` with `local_size_x = local_size`. Work groups run in
parallel (prange); the invocations of one group run in order on one thread. The body
`main(gid, *args)` does its own bounds check, exactly as the shader's `main()` does.

Limits of this emulation (as numba's CUDA simulator documents its own): invocations of a
group run one after another, so a body must not rely on barrier() or shared memory (a shader
that does is mirrored with one local loop per phase, the group's shared memory an array of the
group, and a local that outlives a barrier an array by local id; tests/test_workgroups.py checks
these rules on a shader whose every barrier changes its result). A body with atomics is launched with
`parallel=False`: every invocation then runs in index order, which is one of the orders the
GPU may choose, and the fixed one. There is no FMA contraction, which a GPU compiler may apply.

Subgroup operations (subgroupAdd, subgroupBallot, subgroupShuffle...) end a phase as a barrier does:
the mirror runs a subgroup's invocations one phase at a time, with the locals that outlive a phase in
arrays indexed by the lane, and computes each operation as the loop over the lanes that defines it. The
mirror fixes the subgroup size (32 in sphcore/mc/emit_cubes.py); a shader may use subgroups only where
the size changes no result but an order the host does not depend on (GPUs have 4 to 128 lanes).

Shaders take their compile-time choices as specialization constants; a mirror module
exposes a factory `stage(spec, real)` that builds its body with those values as closure
constants (numba compiles them in, so a disabled term costs nothing), cached per `spec` and
`real`, the float type of the shader build (np.float32, or np.float64: shaders/sph/real.glsl).

A launch keeps its compiled code on disk across runs, one entry per set of closure constants
(sphcore/numba_cache.py); a stage that writes its own launch returns `cached(launch)`, which also
compiles its body and helpers without reference counting: a body must not allocate (no array
slices: copy a vec4 component by component), only the launch may (a work group's shared memory).
`launcher`'s own launches allocate nothing, so they are compiled without it too: with it, each
invocation's call of the body counted each of its arrays up and down, atomically (13 arrays in
compute_density: 9.0 against 7.8 ms at 64,000 particles on 2 cores).
"""
from numba import njit, prange

from sphcore.numba_cache import cached


def launcher(main, parallel=True):
    if parallel:
        # (error_model: x / 0 gives inf or NaN, as in GLSL, not ZeroDivisionError)
        @njit(parallel=True, error_model="numpy", _nrt=False)
        def launch(n_groups, local_size, *args):
            for group in prange(n_groups):
                for lid in range(local_size):
                    gid = group * local_size + lid
                    main(gid, *args)
    else:
        @njit(error_model="numpy", _nrt=False)
        def launch(n_groups, local_size, *args):
            for group in range(n_groups):
                for lid in range(local_size):
                    gid = group * local_size + lid
                    main(gid, *args)

    return cached(launch)


def group_count(n, local_size):
    """Work groups needed to cover n invocations."""
    return (n + local_size - 1) // local_size
