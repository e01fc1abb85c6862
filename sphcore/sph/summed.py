"""The rows whose density a rank of sphcore.parallel sums (P.owned_end > 0: compute_density): those whose coordinate
along the slab axis lies in P.summed_min .. summed_max, its slab widened by a reach less than the halo's depth
(sphcore.decomposition.summed_width); every row on one process (owned_end 0). Why: the shader.

Mirror of shaders/sph/summed.glsl: same names, same statements.
"""
from numba import njit


@njit
def summed_row(P, coordinate):
    return P.owned_end == 0 or (coordinate >= P.summed_min and coordinate < P.summed_max)
