"""Float64 all-pairs reference of the SPH step, written from the equations with numpy.

Independent of the shaders and mirrors (vectorised over neighbours, float64, its own loops, no
grid): the oracle the numba kernels, and through them the shaders, are checked against.
Works in 2D and 3D: x has shape (n, dim).
"""
import math

import numpy as np


def coefficients(h, dim):
    if dim == 2:
        return 4.0 / (math.pi * h**8), -30.0 / (math.pi * h**5), 40.0 / (math.pi * h**5)
    return 315.0 / (64.0 * math.pi * h**9), -45.0 / (math.pi * h**6), 45.0 / (math.pi * h**6)


def images(xi, xj, box_min, box_max, h):
    """Positions of every j and its mirror images across the walls within h of xi, and their flips."""
    dim = len(xi)
    out = [(xj, np.ones(dim))]
    if box_min is None:  # open domain: no walls
        return out
    for axis in range(dim):
        wall = box_min[axis] if xi[axis] - box_min[axis] < h else box_max[axis]
        if abs(xi[axis] - wall) < h:
            flip = np.ones(dim)
            flip[axis] = -1.0
            out += [(np.where(flip < 0, 2 * wall - p, p), f * flip) for p, f in out]
    return out


def neighbours(x, h, box_min=None, box_max=None):
    """For each i, the set of (j, image flips) within h, self excluded (image of self included)."""
    out = []
    for i in range(len(x)):
        found = set()
        for k, (xk, flip) in enumerate(images(x[i], x, box_min, box_max, h)):
            r2 = ((x[i] - xk) ** 2).sum(axis=1)
            for j in np.flatnonzero(r2 < h * h):
                if k == 0 and j == i:
                    continue
                found.add((int(j), tuple(flip)))
        out.append(found)
    return out


def density_pressure(x, mass, h, rest_density, stiffness, box_min, box_max, tait=False):
    poly6 = coefficients(h, x.shape[1])[0]
    rho = np.zeros(len(x))
    for i in range(len(x)):
        for xk, _ in images(x[i], x, box_min, box_max, h):
            r2 = ((x[i] - xk) ** 2).sum(axis=1)
            w = np.where(r2 < h * h, (h * h - r2) ** 3, 0.0)
            rho[i] += mass * poly6 * w.sum()
    if tait:
        p = rest_density * stiffness / 7.0 * ((rho / rest_density) ** 7 - 1.0)
    else:
        p = stiffness * (rho - rest_density)
    return rho, np.maximum(p, 0.0)


def acceleration(x, v, rho, p, mass, h, viscosity, gravity, box_min, box_max, cohesion=0.0):
    dim = x.shape[1]
    poly6, spiky, visc = coefficients(h, dim)
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
                flipped = np.flatnonzero(flip < 0)
                r_hat[z] = 0.0
                if len(flipped) == 0:
                    r_hat[z, 0] = -1.0 if i < np.flatnonzero(near)[z] else 1.0
                else:
                    axis = flipped[-1]
                    r_hat[z, axis] = 1.0 if x[i, axis] - box_min[axis] < h else -1.0
            grad = spiky * (h - rl) ** 2
            coef = mass * (p[i] / rho[i] ** 2 + p[near] / rho[near] ** 2) * grad
            a[i] -= (coef[:, None] * r_hat).sum(axis=0)
            lap = visc * (h - rl)
            a[i] += viscosity / rho[i] * ((mass * lap / rho[near])[:, None] * (v[near] * flip - v[i])).sum(axis=0)
            if k == 0 and cohesion:
                w = poly6 * (h * h - rl**2) ** 3
                a[i] -= cohesion * (w[:, None] * r[near]).sum(axis=0)
        a[i] += gravity
    return a


def shifting_sums(x, rho, mass, h, spacing, box_min, box_max):
    """(grad C, div r) of Lind et al. 2012's shifting (shaders/sph/shifting.glsl) with Mueller's kernels: for each i,
    grad C_i = sum_j (1 + 0.2 (W_ij / W(dx))^4) grad_i W_ij m / rho_j and div r_i = -sum_j r_ij . grad_i W_ij m / rho_j
    over the other particles and the wall images within h (an image carries its particle's density)."""
    dim = x.shape[1]
    _, spiky, _ = coefficients(h, dim)
    w_dx = (h * h - spacing * spacing) ** 3
    grad_c = np.zeros_like(x)
    div_r = np.zeros(len(x))
    for i in range(len(x)):
        for k, (xk, _) in enumerate(images(x[i], x, box_min, box_max, h)):
            r = x[i] - xk
            rlen = np.sqrt((r**2).sum(axis=1))
            near = (rlen < h) & (rlen > 0)
            if k == 0:
                near[i] = False
            rl = rlen[near]
            grad_w = (spiky * (h - rl) ** 2 / rl)[:, None] * r[near]  # grad_i W_ij (spiky < 0: towards j)
            volume = mass / rho[near]
            ratio = (h * h - rl**2) ** 3 / w_dx
            grad_c[i] += (((1 + 0.2 * ratio**4) * volume)[:, None] * grad_w).sum(axis=0)
            div_r[i] -= (volume * (r[near] * grad_w).sum(axis=1)).sum()
    return grad_c, div_r
