"""The parameter block: parsed from shaders/sph/params.glsl, filled from a scene.

The GLSL push-constant block is the single definition. `PARAMS_DTYPE` is a numpy record
dtype with the same field names and std430 offsets, so one `np.ndarray` of one record is
both the bytes pushed to Vulkan and the `params` argument of every numba mirror
(`P = params[0]; P.h`).
"""
import math
import re
from pathlib import Path

import numpy as np

SHADER_DIR = Path(__file__).resolve().parent.parent / "shaders"

# GLSL type -> (numpy base type, components, std430 alignment in bytes)
_GLSL_TYPES = {
    "uint": (np.uint32, 1, 4),
    "int": (np.int32, 1, 4),
    "float": (np.float32, 1, 4),
    "vec2": (np.float32, 2, 8),
    "vec3": (np.float32, 3, 16),
    "vec4": (np.float32, 4, 16),
}


def dtype_from_glsl_block(text):
    """Record dtype of the first `uniform Name { type field; ... }` block in GLSL `text`."""
    body = re.search(r"uniform\s+\w+\s*\{(.*?)\}", text, re.S)
    if body is None:
        raise ValueError("no uniform block found")
    names, formats, offsets, offset = [], [], [], 0
    code = " ".join(line.split("//")[0] for line in body.group(1).splitlines())
    for decl in filter(None, (d.strip() for d in code.split(";"))):
        m = re.fullmatch(r"(\w+)\s+(\w+)", decl)
        if m is None or m.group(1) not in _GLSL_TYPES:
            raise ValueError(f"unsupported declaration in parameter block: {decl!r}")
        base, count, align = _GLSL_TYPES[m.group(1)]
        offset = (offset + align - 1) // align * align
        names.append(m.group(2))
        formats.append(base if count == 1 else (base, (count,)))
        offsets.append(offset)
        offset += 4 * count
    itemsize = (offset + 7) // 8 * 8
    return np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": itemsize})


PARAMS_DTYPE = dtype_from_glsl_block((SHADER_DIR / "sph" / "params.glsl").read_text())


def kernel_coefficients(h, dim=2):
    """Normalisation constants of the Mueller et al. (2003) kernels in `dim` dimensions.

    poly6: W = c (h^2 - r^2)^3; spiky: grad W = c (h - r)^2 r_hat (c < 0);
    viscosity: lap W = c (h - r). Seed 1 used the 3D constants in a 2D simulation;
    the 2D ones below make each kernel integrate to one over the plane.
    """
    if dim != 2:
        raise ValueError(f"dimension {dim} is not supported yet (only 2)")
    return {
        "poly6": 4.0 / (math.pi * h**8),
        "spiky_grad": -30.0 / (math.pi * h**5),
        "visc_lap": 40.0 / (math.pi * h**5),
    }


def lattice_mass(spacing, h, rest_density):
    """Particle mass that makes a full square lattice of `spacing` sum to `rest_density`.

    With h = 2 spacing a particle has about 12 neighbours and the kernel sum on a lattice is
    a few percent off one; scaling the mass removes that bias so a fluid at rest starts at rho_0.
    """
    reach = int(math.ceil(h / spacing))
    offsets = np.arange(-reach, reach + 1) * spacing
    r2 = offsets[:, None] ** 2 + offsets[None, :] ** 2
    q = np.clip(h * h - r2, 0.0, None)
    return rest_density / (kernel_coefficients(h)["poly6"] * np.sum(q**3))


def fold_parameters(n, h, mass, rest_density, stiffness, viscosity, dt, restitution,
                    gravity, box_min, box_max):
    """One record of PARAMS_DTYPE with all constant factors folded in (float32)."""
    c = kernel_coefficients(h)
    params = np.zeros(1, PARAMS_DTYPE)
    p = params[0]
    p["n"] = n
    p["h"] = h
    p["h2"] = h * h
    p["density_coef"] = mass * c["poly6"]
    p["pressure_coef"] = -mass * c["spiky_grad"]
    p["viscosity_coef"] = viscosity * mass * c["visc_lap"]
    p["rest_density"] = rest_density
    p["stiffness"] = stiffness
    p["dt"] = dt
    p["restitution"] = restitution
    p["gravity"] = gravity
    p["box_min"] = box_min
    p["box_max"] = box_max
    return params
