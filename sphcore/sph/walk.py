"""The neighbour walk (TrixiParticles' foreach_neighbor): walk_neighbours, every other particle and every wall or
obstacle image within h of particle i, each handed to `pair`, in the list's or the scan's order (compute_forces,
wall_pressure); walk_list, the list slot by slot (the DFSPH sweeps). walk.glsl says what each serves, and why
compute_density scans with its own loop.

numba has no function the shader's globals could name, so the walk is made per caller: `walk(spec, real, pair)`
(walk_neighbours) closes over the caller's njit'ed
    pair(own, state, i, j, image, r_x, r_y, r_z, r2, inward_x, inward_y, inward_z) -> state
where `own` is a tuple of what the hooks read (i's state, the buffers) and `state` the tuple of the sums, which
the shader keeps in private globals; the walks return the sums. `list_walk(list_entry)` (walk_list) closes over
    list_entry(own, state, i, slot, chunk) -> (chunk, state)

Mirror of shaders/sph/walk.glsl: same names, same statements. A GLSL vec3 `v` is `v_x, v_y, v_z`.
"""
from functools import lru_cache

from numba import njit

from sphcore.sph.cell_ranges import cell_ranges
from sphcore.sph.cells import cells
from sphcore.sph.neighbour_list import neighbour_list
from sphcore.sph.obstacles import obstacles


@lru_cache(maxsize=None)
def walk(spec, real, pair):
    OBSTACLES, MAX_NEIGHBOURS, LIST_SKIN = spec.OBSTACLES, spec.MAX_NEIGHBOURS, spec.LIST_SKIN
    cell_of = cells(spec, real).cell_of
    reflected = cells(spec, real).reflected
    range_count = cells(spec, real).range_count
    cell_range = cell_ranges(spec, real)
    solid = obstacles(spec, real).solid
    mirror_planes = obstacles(spec, real).mirror_planes
    listed_distance = neighbour_list(spec, real).listed_distance

    @njit(inline="always")  # (numba inlines it into its caller: no tuple crosses a call)
    def walk_neighbours(P, particle_x, scratch_x, cell_pyramid, cell_start, obstacle_box, neighbours, neighbour_count, i,
                        xi_x, xi_y, xi_z, own, state):
        """Hands every other particle and image within h of i (at xi) to `pair`; returns the sums `state`."""
        # the wall and obstacle images, as in compute_density (obstacles.glsl: mirror_planes):
        # bit a of `mirrored` says that the wall on axis a, or an obstacle's face where nearer, is within h; `inward`
        # points from each axis's mirror plane into the fluid. Reused lists (LIST_SKIN): the walls and cells of where
        # i was at the list's build (scratch_x)
        x_built_x = scratch_x[i, 0] if LIST_SKIN > 0 else xi_x
        x_built_y = scratch_x[i, 1] if LIST_SKIN > 0 else xi_y
        x_built_z = scratch_x[i, 2] if LIST_SKIN > 0 else xi_z
        mirrored, wall_x, wall_y, wall_z, inward_x, inward_y, inward_z = mirror_planes(
            P, obstacle_box, x_built_x, x_built_y, x_built_z, xi_x, xi_y, xi_z)
        # i's list where it fits its slots, else the scan (below: the list's loop after the scan's, as in
        # walk.glsl, where that order is the GPU's faster one)
        listed = MAX_NEIGHBOURS > 0 and int(neighbour_count[i]) <= MAX_NEIGHBOURS
        # the scan: image `image` mirrors the axes of its bits; the image of j is within h of xi exactly
        # when j is within h of xi's own image xm, so the cells searched are those around xm
        for image in range(8):
            if listed or (image & ~mirrored) != 0:
                continue
            xm_x, xm_y, xm_z = reflected(x_built_x, x_built_y, x_built_z, wall_x, wall_y, wall_z, image)
            base_x, base_y, base_z = cell_of(P, xm_x, xm_y, xm_z)
            # the 3^dim cells around xm, as ranges of sorted particles (cell_ranges.glsl)
            for k in range(range_count()):
                inside, start, end = cell_range(P, cell_pyramid, cell_start, base_x, base_y, base_z, k)
                if not inside:
                    continue
                for j in range(start, end):
                    if j == i and image == 0:
                        continue
                    xk, yk, zk = particle_x[j, 0], particle_x[j, 1], particle_x[j, 2]
                    if image != 0:
                        xk, yk, zk = reflected(xk, yk, zk, wall_x, wall_y, wall_z, image)
                    if OBSTACLES > 0 and image != 0 and not solid(P, obstacle_box, xk, yk, zk):
                        continue  # (obstacles.glsl)
                    r_x = xi_x - xk
                    r_y = xi_y - yk
                    r_z = xi_z - zk
                    r2 = r_x * r_x + r_y * r_y + r_z * r_z
                    if r2 >= P.h2:
                        continue
                    state = pair(own, state, i, j, image, r_x, r_y, r_z, r2, inward_x, inward_y, inward_z)
        # the list
        if listed:
            count = int(neighbour_count[i])
            chunk = (0, 0, 0, 0)
            for slot in range(count):
                chunk, j, image, r_x, r_y, r_z, r2 = listed_distance(P, particle_x, neighbours, i, slot, chunk, xi_x,
                                                                     xi_y, xi_z, wall_x, wall_y, wall_z)
                if LIST_SKIN > 0 and r2 >= P.h2:
                    continue  # (a reused list holds pairs out to list_reach)
                state = pair(own, state, i, j, image, r_x, r_y, r_z, r2, inward_x, inward_y, inward_z)
        return state

    return walk_neighbours


@lru_cache(maxsize=None)
def list_walk(list_entry):
    @njit(inline="always")
    def walk_list(i, count, own, state):
        """Hands the first `count` slots of i's list to `list_entry`, in the list's order, with the chunk they are
        read through (walk.glsl says why this entry point); returns the sums `state`."""
        chunk = (0, 0, 0, 0)
        for slot in range(count):
            chunk, state = list_entry(own, state, i, slot, chunk)
        return state

    return walk_list
