"""DFSPH's state layout (physics.pressure_solver = "dfsph"): indices into control, dfsph_state
and dfsph_history, shared by the dfsph_* mirrors.

Mirror of shaders/sph/dfsph.glsl: same names, same values (the step, the solves and their
equations are described there).
"""
from functools import lru_cache

from numba import njit

SOLVE_DIVERGENCE = 1  # D.level of the divergence-free solve's stages
SOLVE_DENSITY = 2  # D.level of the constant-density solve's stages
SOLVE_WARM_START = 3  # D.level of dfsph_velocity's warm start of the constant-density solve
WARM_START = 0.5  # as SPlisHSPlasH: half the last pressure

# control (uint32)
CONTROL_DONE = 0  # [CONTROL_DONE + solve]: 1 once the solve has stopped this step
CONTROL_ITERATIONS = 2  # [CONTROL_ITERATIONS + solve]: its velocity updates this step
CONTROL_STEP = 5  # steps completed (the device's count: the history's row)
CONTROL_FAILURES = 6  # solves that spent their budget unconverged, since the start
CONTROL_FAILED_STEP = 7  # the first of them: its step (1 = the first step)
CONTROL_FAILED_SOLVE = 8  # and its solve
CONTROL_MAX_ITERATIONS = 9  # fluid.max_iterations (host)
CONTROL_OVERFLOW_STEP = 10  # the first step at which a particle had more than MAX_NEIGHBOURS; 0: none
CONTROL_FINISHED = 11  # dfsph_residual's work groups finished in this dispatch (the last runs the check, resets it)
CONTROL_RUNNING = 12  # 1: the recorded dispatches run; 0 once a solve spent its window (conditional rendering)
CONTROL_WINDOW = 13  # [CONTROL_WINDOW + solve]: the iterations the host recorded per window (0: no window)
CONTROL_DISPATCH = 16  # [dispatch_base(solve)]: the solve's indirect dispatch arguments, (x, y, z) work
#                        groups of its dfsph_velocity and dfsph_residual
CONTROL_REBUILD = 22  # the state equation's reused lists (LIST_SKIN): 1 where the next step builds them
CONTROL_BUILDS = 23  # the builds so far (compute_density)
CONTROL_SIZE = 32
IMAGE_SHIFT = 29  # neighbours: j | image << IMAGE_SHIFT (n < 2^29)
NEIGHBOUR_MASK = (1 << IMAGE_SHIFT) - 1


@njit
def dispatch_base(solve):
    return CONTROL_DISPATCH + 8 * (solve - 1)


def list_width(slots):
    """Words a particle's list of `slots` slots takes: whole chunks of 4 slots (LIST_CHUNKS's, in every layout)."""
    return (slots + 3) // 4 * 4


@njit
def chunk_index(P, i, slot):
    """Chunk of 4 slots (16 bytes) that holds slot `slot` of particle i's slot-major list."""
    return (slot >> 2) * P.n + i


@njit
def lane_of(chunk, lane):
    """chunk[lane], by selects (dfsph.glsl: a GPU may keep a vector indexed by a variable in memory)."""
    return chunk[0] if lane == 0 else chunk[1] if lane == 1 else chunk[2] if lane == 2 else chunk[3]


@njit
def with_lane(chunk, lane, value):
    """GLSL `chunk[lane] = value` for a uvec4 chunk, here a 4-tuple (a new one)."""
    return (value if lane == 0 else chunk[0], value if lane == 1 else chunk[1], value if lane == 2 else chunk[2],
            value if lane == 3 else chunk[3])


@njit
def store_chunk(P, neighbours, i, slot, chunk):
    """GLSL `neighbour_chunks[chunk_index(i, slot)] = chunk`: the 4 words of the chunk that holds `slot`."""
    word = chunk_index(P, i, slot) * 4
    for lane in range(4):
        neighbours[word + lane] = chunk[lane]


@njit
def load_chunk(P, neighbours, i, slot):
    """GLSL `neighbour_chunks[chunk_index(i, slot)]`: the 4 words of the chunk that holds `slot`, as a 4-tuple."""
    word = chunk_index(P, i, slot) * 4
    return (int(neighbours[word]), int(neighbours[word + 1]), int(neighbours[word + 2]),
            int(neighbours[word + 3]))


@lru_cache(maxsize=None)
def list_slots(spec):
    """`list_slot(P, i, slot)` of the spec's list layout (LIST_BY_PARTICLE: particle-major, else slot-major, with
    LIST_CHUNKS in chunks of 4 slots)."""
    MAX_NEIGHBOURS, LIST_BY_PARTICLE, LIST_CHUNKS = spec.MAX_NEIGHBOURS, spec.LIST_BY_PARTICLE, spec.LIST_CHUNKS

    @njit
    def list_slot(P, i, slot):
        if LIST_BY_PARTICLE:
            return i * MAX_NEIGHBOURS + slot
        return chunk_index(P, i, slot) * 4 + (slot & 3) if LIST_CHUNKS else slot * P.n + i

    return list_slot

# dfsph_state (float32)
STATE_TOLERANCE = 0  # [STATE_TOLERANCE + solve]: fluid.max_divergence_error, max_density_error
STATE_ERROR = 2  # [STATE_ERROR + solve]: the error the solve stopped at this step
STATE_FAILED_ERROR = 5  # the error the first unconverged solve stopped at
STATE_RELAXATION = 6  # fluid.relaxation (host): the share omega of each Jacobi update applied
STATE_SIZE = 8

# dfsph_history (float32, HISTORY_COLUMNS a row)
HISTORY_ROWS = 256
HISTORY_COLUMNS = 8  # step, dt, time, divergence iterations, divergence error, density iterations,
#                      density error, 1 where both converged
MIN_ITERATIONS_DIVERGENCE = 1
MIN_ITERATIONS_DENSITY = 2
