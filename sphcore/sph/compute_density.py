"""Density and pressure, one invocation per particle. Neighbours from the grid (GRID) or all
pairs; wall and obstacle-face images (WALLS, OBSTACLES); linear or Tait equation of state (TAIT).
The kernel is kernels.glsl's (KERNEL). Summation density, or with CONTINUITY the rate d rho/dt
(particle_drho) of the density that integrate.comp integrates, with density diffusion
(DENSITY_DIFFUSION). With neighbour lists (MAX_NEIGHBOURS > 0) the scan also writes each particle's
list (dfsph.py), which compute_forces walks, and under DFSPH dfsph_factor and the solves. Lists reused
between builds (LIST_SKIN, cells.glsl: list_reach): a build (D.level 0) lists out to list_reach and keeps where
each particle was (scratch_x); a step between builds (D.level 1) walks the lists instead of the cells. The scan is
walk.py's written out, not called through its hooks (walk.glsl says why).

Mirror of shaders/sph/compute_density.comp: same names, same statement order, same step
labels. A GLSL vec3 local `v` is `v_x, v_y, v_z` here.
"""
from functools import lru_cache

import numpy as np
from numba import njit

from sphcore.sph.cells import cells, skin
from sphcore.sph.density_diffusion import density_diffusion
from sphcore.sph.dfsph import CONTROL_BUILDS, IMAGE_SHIFT, list_slots, store_chunk, with_lane
from sphcore.sph.equation_of_state import equation_of_state
from sphcore.sph.kernels import kernels
from sphcore.sph.neighbour_list import neighbour_list
from sphcore.sph.obstacles import obstacles
from sphcore.sph.pairs import pairs
from sphcore.sph.summed import summed_row
from sphcore.workgroups import launcher



@njit
def neighbour_hash(id, image):
    """Order-independent fingerprint of a neighbour (id, image): a 32-bit mix summed over the set."""
    h = ((id * 8 + image) * 0x9E3779B1) & 0xFFFFFFFF
    h ^= h >> 15
    h = (h * 0x85EBCA77) & 0xFFFFFFFF
    h ^= h >> 13
    return h


def can_list_first(spec):
    """Whether the spec's scan writes lists and sums the density, where BRANCH_FREE_SCAN lists first."""
    return spec.MAX_NEIGHBOURS > 0 and not spec.CONTINUITY and not spec.NEIGHBOUR_STATS and spec.LIST_SKIN == 0


@lru_cache(maxsize=None)
def compute_density(spec, real=np.float32):
    DIM, GRID, NEIGHBOUR_STATS = spec.DIM, spec.GRID, spec.NEIGHBOUR_STATS
    cell_of = cells(spec, real).cell_of
    reflected = cells(spec, real).reflected
    range_count = cells(spec, real).range_count
    range_cells = cells(spec, real).range_cells
    list_reach = skin(spec, real).list_reach
    listed_distance = neighbour_list(spec, real).listed_distance
    LIST_SKIN = spec.LIST_SKIN
    mirror_planes = obstacles(spec, real).mirror_planes
    solid = obstacles(spec, real).solid
    OBSTACLES = spec.OBSTACLES
    CONTINUITY, DENSITY_DIFFUSION, BODIES = spec.CONTINUITY, spec.DENSITY_DIFFUSION, spec.BODIES
    MAX_NEIGHBOURS = spec.MAX_NEIGHBOURS
    # A scan with no branch on the distance (BRANCH_FREE_SCAN, where the list is written and the density summed):
    # once the flow has lost its lattice a CPU mispredicts that branch, about one candidate in seven being a
    # neighbour. Every candidate goes into the list's next slot, which only one within h keeps, self included;
    # the kernel is then summed over the list in the scan's order and self taken out of it (listed_sum): the
    # same bits as the scan with the branch. Before a cell range that could fill the list, it is summed, and the
    # scan goes on with the branch.
    LIST_FIRST = spec.BRANCH_FREE_SCAN and can_list_first(spec)
    # A list in chunks (LIST_CHUNKS, dfsph.glsl: list_slot) is written a chunk of 4 entries at a time, gathered in
    # `chunk`: one 16-byte store where the GPU paid for four scattered ones (a list-first scan writes entry by entry).
    CHUNKED = spec.LIST_CHUNKS and not spec.LIST_BY_PARTICLE and not LIST_FIRST
    list_slot = list_slots(spec)
    kernel_w = kernels(spec, real).kernel_w
    pair_gradient = kernels(spec, real).pair_gradient
    pair_direction = pairs(real)
    diffusion_term = density_diffusion(spec, real).diffusion_term
    equation_of_state_ = equation_of_state(spec, real)

    @njit
    def listed_sum(P, particle_x, neighbours, i, xi_x, xi_y, xi_z, wall_x, wall_y, wall_z, count, sum_w):
        """Adds kernel_w over the `count` entries of i's list (a list-first scan's, self among them) to sum_w
        in the list's order, and takes self out of the list: returns (the others' count, sum_w)."""
        self_seen = 0
        chunk = (0, 0, 0, 0)
        for slot in range(count):
            chunk, j, image, r_x, r_y, r_z, r2 = listed_distance(P, particle_x, neighbours, i, slot, chunk, xi_x,
                                                                 xi_y, xi_z, wall_x, wall_y, wall_z)
            sum_w += kernel_w(P, r2)
            neighbours[list_slot(P, i, slot - self_seen)] = j | (image << IMAGE_SHIFT)
            self_seen |= int(j == i and image == 0)
        return count - self_seen, sum_w

    @njit
    def add_rate(P, particle_x, particle_v, particle_rho, particle_id, i, j, image, r_x, r_y, r_z, r2, xi_x, xi_y, xi_z, vi_x, vi_y,
                 vi_z, rhoi, inward_x, inward_y, inward_z, sum_div, sum_diffusion):
        """Continuity density: one other particle's or image's terms of d rho_i/dt, at r = xi - x_k
        within h (k: j's image across the walls of `image`'s bits), added to sum_div and sum_diffusion (returned);
        the scan's and a reused list's walk's. A wall particle of the bodies (BODIES) is fixed: its velocity here is
        0; it takes part in the diffusion with the density of its extrapolated pressure (as the .comp says why)."""
        # the direction r_hat from the neighbour to i (pairs.glsl); an image's velocity is mirrored on its
        # flipped axes
        rlen = np.sqrt(r2)
        r_hat_x, r_hat_y, r_hat_z = pair_direction(r_x, r_y, r_z, rlen, i, j, image, inward_x, inward_y, inward_z)
        wall_j = BODIES and particle_id[j] >= P.fluid_count
        vj_x = real(0.0) if wall_j else particle_v[j, 0]
        vj_y = real(0.0) if wall_j else particle_v[j, 1]
        vj_z = real(0.0) if wall_j else particle_v[j, 2]
        vk_x = -vj_x if (image & 1) != 0 else vj_x
        vk_y = -vj_y if (image & 2) != 0 else vj_y
        vk_z = -vj_z if (image & 4) != 0 else vj_z
        v_r = (vi_x - vk_x) * r_hat_x + (vi_y - vk_y) * r_hat_y + (vi_z - vk_z) * r_hat_z
        # d rho_i/dt = sum_j m (v_i - v_j) . grad_i W_ij = -pressure_coef sum_j kernel_gradient v_ij . r_hat
        sum_div += pair_gradient(P, r2, rlen, image) * v_r
        # density diffusion D_i (density_diffusion.glsl) at the pair's (or image's) distance; an image carries
        # its particle's density, so its hydrostatic difference is its particle's
        if DENSITY_DIFFUSION > 0:
            sum_diffusion += diffusion_term(P, rhoi, particle_rho[j], particle_x[j, 0] - xi_x, particle_x[j, 1] - xi_y,
                                            particle_x[j, 2] - xi_z, r2, rlen)
        return sum_div, sum_diffusion

    @njit
    def compute_density_main(i, params, particle_x, particle_v, particle_rho, particle_p, cell_pyramid, cell_start,
                             scratch_x, particle_id, particle_neighbours, obstacle_box, particle_drho, control,
                             neighbours, neighbour_count):
        P = params[0]
        D = params[0]  # (the dispatch's push constants: on numba, fields of the same record)
        # [1] one invocation per particle; the grid is rounded up to whole work groups. On a rank of sphcore.parallel
        #     the rows whose density a step reads alone (summed.py; the others keep what they held)
        if i >= P.n:
            return
        if LIST_SKIN > 0 and D.level != 1 and i == 0:
            control[CONTROL_BUILDS] += 1
        if not summed_row(P, particle_x[i, DIM - 1]):
            return
        # [2] own position; with continuity density also the velocity and the density (state)
        xi_x = particle_x[i, 0]
        xi_y = particle_x[i, 1]
        xi_z = particle_x[i, 2]
        vi_x = real(0.0)
        vi_y = real(0.0)
        vi_z = real(0.0)
        rhoi = real(0.0)
        if CONTINUITY:
            vi_x = particle_v[i, 0]
            vi_y = particle_v[i, 1]
            vi_z = particle_v[i, 2]
            rhoi = particle_rho[i]
        # [3] wall images: within h of a wall, particle i also sees every particle mirrored across
        #     it (ghost fluid: free-slip boundary of Takeda et al. 1994). Bit a of `mirrored` says
        #     that the wall nearer to xi on axis a is within h; an obstacle's face in front of xi
        #     takes the place of its axis's wall where nearer (obstacles.glsl). Reused lists (LIST_SKIN): the walls
        #     within list_reach of where i was at the list's build (this step's position at a build, D.level 0)
        walk = LIST_SKIN > 0 and D.level == 1
        x_built_x = scratch_x[i, 0] if walk else xi_x
        x_built_y = scratch_x[i, 1] if walk else xi_y
        x_built_z = scratch_x[i, 2] if walk else xi_z
        mirrored, wall_x, wall_y, wall_z, inward_x, inward_y, inward_z = mirror_planes(
            P, obstacle_box, x_built_x, x_built_y, x_built_z, xi_x, xi_y, xi_z)
        # [4] sum kernel_w over every particle and image within h, self included (with
        #     NEIGHBOUR_STATS, also count them and sum a hash of each (id, image): the set's fingerprint). Image
        #     `image` mirrors the axes of its bits; the image of j is within h of xi exactly when j
        #     is within h of xi's own image xm, so the cells searched are those around xm.
        #     Continuity: sum the velocity divergence and the diffusion term over the others instead.
        #     Lists: each of the others into the list, in the scan's order, j | image << IMAGE_SHIFT
        #     (LIST_FIRST: every candidate first, summed from the list after; CHUNKED: by chunks of 4). A build of
        #     reused lists lists the others within list_reach
        sum_w = real(0.0)
        sum_div = real(0.0)
        sum_diffusion = real(0.0)
        found = 0
        fingerprint = 0
        count = 0
        listing = LIST_FIRST
        chunk = (0, 0, 0, 0)
        reach2 = list_reach(P) * list_reach(P)
        scanning = True
        if walk:  # [5] a reused list: self, and the listed particles and images now within h, in the list's order
            #         (continuity: the others' rates, add_rate); a list that overflowed at its build scans the
            #         cells of the build around x_built instead
            count = int(neighbour_count[i])
            scanning = count > MAX_NEIGHBOURS
        if not scanning:
            sum_w = kernel_w(P, real(0.0))
            for slot in range(count):
                chunk, j, image, r_x, r_y, r_z, r2 = listed_distance(P, particle_x, neighbours, i, slot, chunk,
                                                                     xi_x, xi_y, xi_z, wall_x, wall_y, wall_z)
                if r2 >= P.h2:
                    continue
                if not CONTINUITY:
                    sum_w += kernel_w(P, r2)
                if CONTINUITY:
                    sum_div, sum_diffusion = add_rate(P, particle_x, particle_v, particle_rho, particle_id, i, j, image, r_x, r_y,
                                                      r_z, r2, xi_x, xi_y, xi_z, vi_x, vi_y, vi_z, rhoi, inward_x,
                                                      inward_y, inward_z, sum_div, sum_diffusion)
        for image in range(8):
            if not scanning or (image & ~mirrored) != 0:
                continue
            xm_x, xm_y, xm_z = reflected(x_built_x, x_built_y, x_built_z, wall_x, wall_y, wall_z, image)
            base_x, base_y, base_z = cell_of(P, xm_x, xm_y, xm_z)
            # [6] the 3^dim cells around xm, as ranges of sorted particles (cells.glsl: range_cells; written out, as
            #     in the .comp, which says why)
            for k in range(range_count()):
                start = 0
                end = int(P.n)
                if GRID:
                    inside, first, last = range_cells(P, base_x, base_y, base_z, k)
                    if not inside:
                        continue
                    start = int(cell_start[first])
                    end = int(cell_start[last]) + int(cell_pyramid[last])
                if listing and count + (end - start) > MAX_NEIGHBOURS:  # the list may fill: summed now, and the
                    count, sum_w = listed_sum(P, particle_x, neighbours, i, xi_x, xi_y, xi_z, wall_x, wall_y,
                                              wall_z, count, sum_w)  # rest scanned with the branch
                    listing = False
                for j in range(start, end):
                    xk, yk, zk = particle_x[j, 0], particle_x[j, 1], particle_x[j, 2]
                    if image != 0:
                        xk, yk, zk = reflected(xk, yk, zk, wall_x, wall_y, wall_z, image)
                    if OBSTACLES > 0 and image != 0 and not solid(P, obstacle_box, xk, yk, zk):
                        continue  # (obstacles.glsl)
                    r_x = xi_x - xk
                    r_y = xi_y - yk
                    r_z = xi_z - zk
                    r2 = r_x * r_x + r_y * r_y + r_z * r_z
                    if listing:  # (list first: every candidate into the next slot, kept by one within h)
                        neighbours[list_slot(P, i, count)] = j | (image << IMAGE_SHIFT)
                        count += int(r2 < P.h2)
                        continue
                    within = r2 < P.h2
                    if within or (LIST_SKIN > 0 and not walk and r2 < reach2):
                        if not CONTINUITY and within:
                            sum_w += kernel_w(P, r2)
                        if NEIGHBOUR_STATS and within:
                            found += 1
                            fingerprint = (fingerprint + neighbour_hash(np.int64(particle_id[j]), image)) & 0xFFFFFFFF
                        if MAX_NEIGHBOURS > 0 and not walk and (j != i or image != 0):
                            if count < MAX_NEIGHBOURS:
                                pair = j | (image << IMAGE_SHIFT)
                                if CHUNKED:
                                    chunk = with_lane(chunk, count & 3, pair)
                                    if (count & 3) == 3:
                                        store_chunk(P, neighbours, i, count, chunk)
                                else:
                                    neighbours[list_slot(P, i, count)] = pair
                            count += 1
                    # [7] continuity: the rates of the others within h (add_rate: the velocity divergence, d rho_i/dt,
                    #     and the density diffusion D_i)
                    if CONTINUITY and within and (j != i or image != 0):
                        sum_div, sum_diffusion = add_rate(P, particle_x, particle_v, particle_rho, particle_id, i, j, image, r_x,
                                                          r_y, r_z, r2, xi_x, xi_y, xi_z, vi_x, vi_y, vi_z, rhoi,
                                                          inward_x, inward_y, inward_z, sum_div, sum_diffusion)
        if listing:
            count, sum_w = listed_sum(P, particle_x, neighbours, i, xi_x, xi_y, xi_z, wall_x, wall_y, wall_z,
                                      count, sum_w)
        kept = min(count, MAX_NEIGHBOURS)
        if CHUNKED and not walk and (kept & 3) != 0:
            store_chunk(P, neighbours, i, kept, chunk)  # (the last chunk's rest: unread)
        # [8] summation: rho_i = m sum_j W(r_ij, h); continuity: the state's rho_i, and its rate (which
        #     integrate_density, the next stage, adds: it needs every neighbour's density unchanged here)
        rho = P.density_coef * sum_w
        drho = real(0.0)
        if CONTINUITY:
            rho = rhoi
            drho = -P.pressure_coef * sum_div
            if DENSITY_DIFFUSION > 0:
                drho += P.diffusion_coef * sum_diffusion
        # [9] equation of state (equation_of_state.glsl: linear or Tait; clamped at 0 with summation
        #     density only)
        p = equation_of_state_(P, rho)
        # [10] store
        if not CONTINUITY:
            particle_rho[i] = rho
        particle_p[i] = p
        if CONTINUITY:
            particle_drho[i] = drho
        if NEIGHBOUR_STATS:
            particle_neighbours[i, 0] = found
            particle_neighbours[i, 1] = fingerprint
        if MAX_NEIGHBOURS > 0 and not walk:
            neighbour_count[i] = count  # (longer than its slots: compute_forces scans, DFSPH stops)
        if LIST_SKIN > 0 and not walk:
            for c in range(4):
                scratch_x[i, c] = particle_x[i, c]  # (where the list was built: integrate, the walks)

    return launcher(compute_density_main)
