"""Float64 all-pairs reference of the SPH step, written from the equations with numpy.

Independent of the shaders and mirrors (vectorised over neighbours, float64, its own loops):
the oracle the numba kernels are checked against.
"""
import math

import numpy as np


def images(xi, xj, box_min, box_max, h):
    """Positions of every j and its mirror images across the walls within h of xi, and their flips."""
    out = [(xj, np.array([1.0, 1.0]))]
    for axis in range(2):
        if xi[axis] - box_min[axis] < h:
            wall = box_min[axis]
        else:
            wall = box_max[axis]
        if abs(xi[axis] - wall) < h:
            flip = np.array([1.0, 1.0])
            flip[axis] = -1.0
            out += [(np.where(flip < 0, 2 * wall - p, p), f * flip) for p, f in out]
    return out


def density_pressure(x, mass, h, rest_density, stiffness, box_min, box_max):
    rho = np.zeros(len(x))
    for i in range(len(x)):
        for xk, _ in images(x[i], x, box_min, box_max, h):
            r2 = ((x[i] - xk) ** 2).sum(axis=1)
            w = np.where(r2 < h * h, (h * h - r2) ** 3, 0.0)
            rho[i] += mass * 4.0 / (math.pi * h**8) * w.sum()
    return rho, np.maximum(stiffness * (rho - rest_density), 0.0)


def acceleration(x, v, rho, p, mass, h, viscosity, gravity, box_min, box_max):
    a = np.zeros_like(x)
    for i in range(len(x)):
        for k, (xk, flip) in enumerate(images(x[i], x, box_min, box_max, h)):
            r = x[i] - xk
            rlen = np.sqrt((r**2).sum(axis=1))
            near = rlen < h
            if k == 0:
                near[i] = False
            rl = rlen[near]
            r_hat = r[near] / np.where(rl > 0, rl, 1.0)[:, None]
            # coincident pairs: an image lies on the wall (push along the inward normal of the
            # last mirrored axis); two particles are pushed apart along x by index order
            for z in np.flatnonzero(rl == 0):
                axis = 1 if flip[1] < 0 else 0 if flip[0] < 0 else None
                if axis is None:
                    r_hat[z] = (-1.0 if i < np.flatnonzero(near)[z] else 1.0, 0.0)
                else:
                    r_hat[z] = 0.0
                    r_hat[z, axis] = 1.0 if x[i, axis] - box_min[axis] < h else -1.0
            grad = -30.0 / (math.pi * h**5) * (h - rl) ** 2
            coef = mass * (p[i] / rho[i] ** 2 + p[near] / rho[near] ** 2) * grad
            a[i] -= (coef[:, None] * r_hat).sum(axis=0)
            lap = 40.0 / (math.pi * h**5) * (h - rl)
            a[i] += viscosity / rho[i] * ((mass * lap / rho[near])[:, None] * (v[near] * flip - v[i])).sum(axis=0)
        a[i] += gravity
    return a
