"""Pressure sensors on a wall: what a flush-mounted transducer reads, from the particles.

A sensor at point s reads the Shepard-normalised kernel sum of the particles' pressures around it,

    p(s) = sum_j p_j w(|s - x_j|) / sum_j w(|s - x_j|),   w(r) = (h^2 - r^2)^3 for r < h,

over the particles and their wall images, as the solver sees them (compute_density: within h of
a wall, every particle is mirrored across it, and across both walls of a corner). Why on the
wall and with the images, not at a point h/2 inside the fluid:

- At a wall at rest the normal component of the momentum equation gives dp/dn = rho g_n: zero
  on a vertical wall (the dam break's P1, the tank's side sensors). The pressure near the wall is
  then even in the normal distance to first order, which is the field the mirror images
  continue; the images make the kernel's support whole, so the average of a field linear along
  the wall is exact on a symmetric lattice, without moving the sensor off the wall.
- A point h/2 inside reads the pressure h/2 from the wall, which differs from the wall's by
  rho g_n h/2 (zero on a vertical wall, like the above) plus the impact's normal gradient; and
  with fluid on one side only its Shepard average is biased toward the interior. On the wall
  both bias and offset vanish where the physics says dp/dn = 0.
- No particle within h: the sensor is dry and reads 0, as the experiment's transducers do.

Near the floor (a sensor less than h above it) the floor's images count too: they carry the
pressure of the particle they mirror, so a hydrostatic field reads the pressure at the mean
height of the particles around the sensor, low by at most rho g h / 2 (the tests bound it).
"""
import numpy as np


def images(x, box_min, box_max, point, h):
    """[(positions, mask)] of the particles `x` and of their mirror images across every wall of
    the box within h of `point` (and both walls of a corner): an image across the low wall of axis
    a is 2 box_min[a] - x[a]; `mask` selects the particles whose image lies within h of point."""
    dim = x.shape[1]
    walls = []
    for a in range(dim):
        if point[a] - box_min[a] < h:
            walls.append((a, box_min[a]))
        elif box_max[a] - point[a] < h:
            walls.append((a, box_max[a]))
    out = []
    for bits in range(1 << len(walls)):
        y = x.copy()
        for k, (a, plane) in enumerate(walls):
            if bits >> k & 1:
                y[:, a] = 2.0 * plane - y[:, a]
        out.append(y)
    return out


def wall_pressure(x, p, point, h, box_min, box_max):
    """The pressure a sensor at `point` reads (module docstring): particles at x (N, dim) with
    pressures p (N,), the walls of the box [box_min, box_max], smoothing length h. 0 where dry."""
    point = np.asarray(point, np.float64)
    x = np.asarray(x, np.float64)
    p = np.asarray(p, np.float64)
    # a particle or an image within h of the point: the particle within 3 h of it (the point is
    # within h of each wall it is mirrored across, so an image lies at most 2 h further)
    near = (np.abs(x - point) < 3 * h).all(axis=1)
    xs, ps = x[near], p[near]
    total = weighted = 0.0
    for y in images(xs, box_min, box_max, point, h):
        w = np.clip(h * h - ((y - point) ** 2).sum(axis=1), 0.0, None) ** 3
        total += w.sum()
        weighted += (w * ps).sum()
    return float(weighted / total) if total > 0 else 0.0


def wall_pressures(x, p, points, h, box_min, box_max):
    """{name: pressure} of the sensors `points` {name: point}."""
    return {name: wall_pressure(x, p, s, h, box_min, box_max) for name, s in points.items()}


def running_mean(t, values, width):
    """The mean of `values` over a window of about `width` centred on each sample (as many samples
    either side, fewer at the ends), for samples about evenly spaced in time `t`."""
    half = max(0, int(round(width / np.median(np.diff(t)) / 2))) if len(t) > 1 else 0
    cumulative = np.concatenate([[0.0], np.cumsum(values)])
    k = np.arange(len(t))
    lo, hi = np.maximum(k - half, 0), np.minimum(k + half + 1, len(t))
    return (cumulative[hi] - cumulative[lo]) / (hi - lo)
