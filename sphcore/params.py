"""The parameter block: parsed from shaders/sph/params.glsl, filled from a scene.

The GLSL blocks are the single definition: `Params`, a uniform buffer written once (binding
PARAMS_BINDING), and `Dispatch`, the push constants of what changes from one dispatch to the next.
`PARAMS_DTYPE` is a numpy record dtype with Params' field names and offsets followed by Dispatch's, so
one `np.ndarray` of one record is the `params` argument of every numba mirror (`P = params[0]; P.h`;
`D = params[0]; D.level`) and, its first UNIFORM_BYTES, the bytes of Vulkan's uniform buffer.
"""
import math
import re
from collections import namedtuple

import numpy as np

from sphcore.paths import SHADER_DIR

# GLSL type -> (numpy base type, components, std430 alignment in bytes)
_GLSL_TYPES = {
    "uint": (np.uint32, 1, 4),
    "int": (np.int32, 1, 4),
    "float": (np.float32, 1, 4),
    "vec2": (np.float32, 2, 8),
    "vec3": (np.float32, 3, 16),
    "vec4": (np.float32, 4, 16),
    "uvec3": (np.uint32, 3, 16),
}


def dtype_from_glsl_block(text, name=r"\w+"):
    """Record dtype of the first `uniform Name { type field; ... }` block in GLSL `text` (of the block
    called `name`, if given). The offsets are std430's, which are std140's for scalars and vectors."""
    body = re.search(rf"uniform\s+{name}\s*\{{(.*?)\}}", text, re.S)
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


def _joined(first, second):
    """A record dtype of `first`'s fields, then `second`'s from `first.itemsize` on."""
    fields = {**{k: v[:2] for k, v in first.fields.items()},
              **{k: (v[0], first.itemsize + v[1]) for k, v in second.fields.items()}}
    return np.dtype({"names": list(fields), "formats": [f for f, _ in fields.values()],
                     "offsets": [o for _, o in fields.values()], "itemsize": first.itemsize + second.itemsize})


_PARAMS_GLSL = (SHADER_DIR / "sph" / "params.glsl").read_text()
PARAMS_BINDING = int(re.search(r"binding\s*=\s*(\d+)\)\s*uniform\s+Params", _PARAMS_GLSL).group(1))
UNIFORM_DTYPE = dtype_from_glsl_block(_PARAMS_GLSL, "Params")  # Vulkan's uniform buffer
DISPATCH_DTYPE = dtype_from_glsl_block(_PARAMS_GLSL, "Dispatch")  # and push constants
UNIFORM_BYTES = UNIFORM_DTYPE.itemsize
# the numba mirrors' record: both blocks' fields (`P = params[0]; P.h`, `D = params[0]; D.level`)
PARAMS_DTYPE = _joined(UNIFORM_DTYPE, DISPATCH_DTYPE)
MC_PARAMS_DTYPE = dtype_from_glsl_block((SHADER_DIR / "mc" / "params.glsl").read_text())


KERNELS = ("mueller", "wendland_c2")  # scene key physics.kernel; the index is specialization constant KERNEL


def kernel_coefficients(h, dim=2, kernel="mueller"):
    """Normalisation constants of the kernels of shaders/sph/kernels.glsl in `dim` dimensions,
    support radius h. Generic keys, one per helper: W = w * kernel_w, grad_i W = -gradient *
    kernel_gradient * r_hat, L = laplacian * kernel_laplacian.

    mueller (Mueller et al. 2003): poly6: W = c (h^2 - r^2)^3; spiky: grad W = c (h - r)^2 r_hat
    (c < 0); viscosity: lap W = c (h - r). Seed 1 used the 3D constants in a 2D simulation;
    the 2D ones below make each kernel integrate to one over the plane.
    wendland_c2: W = sigma (1 - q)^4 (1 + 4 q), q = r / h, sigma = 7 / (pi h^2) (2D),
    21 / (2 pi h^3) (3D); |grad W| = (20 sigma / h) q (1 - q)^3; L = -2 r . grad W / (r^2 + 0.01 h^2)
    (Morris et al. 1997), coefficient 2 * 20 sigma / h.
    """
    if dim not in (2, 3):
        raise ValueError(f"dimension must be 2 or 3, got {dim}")
    if kernel == "mueller":
        if dim == 2:
            c = {"poly6": 4.0 / (math.pi * h**8), "spiky_grad": -30.0 / (math.pi * h**5),
                 "visc_lap": 40.0 / (math.pi * h**5)}
        else:
            c = {"poly6": 315.0 / (64.0 * math.pi * h**9), "spiky_grad": -45.0 / (math.pi * h**6),
                 "visc_lap": 45.0 / (math.pi * h**6)}
        return {**c, "w": c["poly6"], "gradient": -c["spiky_grad"], "laplacian": c["visc_lap"]}
    if kernel == "wendland_c2":
        sigma = 7.0 / (math.pi * h**2) if dim == 2 else 21.0 / (2.0 * math.pi * h**3)
        return {"w": sigma, "gradient": 20.0 * sigma / h, "laplacian": 40.0 * sigma / h}
    raise ValueError(f"unknown kernel {kernel!r}: choose one of {', '.join(KERNELS)}")


def kernel_shape(r2, h, kernel="mueller"):
    """kernels.glsl's kernel_w at squared distances r2 (numpy, float64; 0 beyond h): W over
    kernel_coefficients(...)["w"]."""
    r2 = np.asarray(r2, np.float64)
    if kernel == "wendland_c2":
        q = np.clip(np.sqrt(r2) / h, 0.0, 1.0)
        return (1.0 - q) ** 4 * (1.0 + 4.0 * q)
    return np.clip(h * h - r2, 0.0, None) ** 3


def lattice_mass(spacing, h, rest_density, dim=2, kernel="mueller"):
    """Particle mass that makes a full square (cubic) lattice of `spacing` sum to `rest_density`
    with the scene's kernel.

    With h = 2 spacing the kernel sum on a lattice is a few percent off one; scaling the mass
    removes that bias so a fluid at rest starts at rho_0.
    """
    reach = int(math.ceil(h / spacing))
    offsets = np.arange(-reach, reach + 1) * spacing
    r2 = sum(np.meshgrid(*[offsets**2] * dim, indexing="ij"))
    return rest_density / (kernel_coefficients(h, dim, kernel)["w"] * np.sum(kernel_shape(r2, h, kernel)))


# Cells are h wide, padded by 2^-12: a pair closer than h is then never two cells apart, even
# after float32 rounding of both cell coordinates (the error is far below 2^-12 of a cell).
CELL_PADDING = 1.0 + 2.0**-12
MAX_CELLS = 1 << 26
MAX_OBSTACLES = 8  # box obstacles a scene may have: the obstacle_box buffer holds (min, max) of each


def pyramid_levels(cell_total):
    """HistoPyramid levels above the base (8 children per node) and the buffer size of all levels."""
    levels, size, total = 0, cell_total, cell_total
    while size > 1:
        size = (size + 7) // 8
        total += size
        levels += 1
    return levels, total


def fold_parameters(n, dim, h, mass, rest_density, stiffness, tait, viscosity, cohesion, dt, restitution,
                    gravity, box_min, box_max, grid_dim=(1, 1, 1), kernel="mueller", density_diffusion="none",
                    diffusion_delta=0.1, gravity_on=True, viscosity_model="laminar", alpha=0.0, cfl_number=0.0,
                    reach=None, cell_split=1, spacing=0.0, shifting=0.0, fluid_count=None):
    """One record of PARAMS_DTYPE with all constant factors folded in (float32). Vectors of
    `dim` components are padded with zeros to three. `kernel`: physics.kernel; `density_diffusion`
    ("none" | "molteni" | "fourtakas") with coefficient `diffusion_delta` (fluid.density_diffusion);
    `gravity_on`: physics.gravity (the hydrostatic part of Fourtakas' diffusion needs it).
    `viscosity_model` ("laminar" | "artificial"; physics.viscosity_model): laminar takes `viscosity`
    (mu), artificial `alpha` (fluid.alpha; viscosity_coef = alpha c h, c = sqrt(stiffness));
    `cfl_number`: 0.25 time.dt_fraction where time.dt = "adaptive" (then `dt` is the largest step).
    The grid's cells are `cell_split` to the search's `reach` (h, or a reused list's; CELL_SPLIT).
    `shifting`: A of physics.shifting = "lind" (fluid.shifting; 0: none), at the lattice's `spacing` dx.
    `fluid_count`: the fluid's particles among the n (default all; the rest are the bodies' wall particles)."""
    c = kernel_coefficients(h, dim, kernel)
    pad = lambda v: list(v) + [0.0] * (3 - len(v))  # noqa: E731
    params = np.zeros(1, PARAMS_DTYPE)
    p = params[0]
    p["n"] = n
    p["fluid_count"] = n if fluid_count is None else fluid_count
    p["h"] = h
    p["h2"] = h * h
    p["density_coef"] = mass * c["w"]
    p["pressure_coef"] = mass * c["gradient"]
    p["viscosity_coef"] = viscosity * mass * c["laplacian"]
    if viscosity_model == "artificial":  # Monaghan 1992's alpha c h (shaders/sph/viscosity.glsl)
        p["viscosity_coef"] = alpha * math.sqrt(stiffness) * h
    p["cohesion_coef"] = -cohesion * c["w"]
    p["rest_density"] = rest_density
    # Tait: B = rho_0 c^2 / 7 gives the linear law's sound speed c = sqrt(k) at rho_0
    p["stiffness"] = rest_density * stiffness / 7.0 if tait else stiffness
    p["dt"] = dt
    p["restitution"] = restitution
    p["inv_cell"] = cell_split / ((reach or h) * CELL_PADDING)  # cell_split cells to the search's reach
    p["gravity"] = pad(gravity)
    p["box_min"] = pad(box_min)
    p["box_max"] = pad(box_max)
    p["grid_dim"] = grid_dim
    p["cell_total"] = int(np.prod(grid_dim))
    p["levels"] = pyramid_levels(int(np.prod(grid_dim)))[0]
    # delta-SPH (Molteni & Colagrossi 2009): D_i = delta h_s c_0 sum_j psi_ij . grad_i W_ij V_j with
    # psi_ij = 2 (rho_j - rho_i) r_ji / r^2 and h_s = h / 2 (half the support: the smoothing length of the
    # customary delta = 0.1; DualSPHysics folds the same 2 delta h_s = delta times the support); with
    # r_ji . m grad_i W_ij = pressure_coef kernel_gradient r, that is diffusion_coef sum_j (rho_j - rho_i)
    # / rho_j kernel_gradient r / (r^2 + 0.01 h^2) (density_diffusion.glsl)
    if density_diffusion != "none":
        p["diffusion_coef"] = diffusion_delta * h * math.sqrt(stiffness) * mass * c["gradient"]
    if density_diffusion == "fourtakas" and gravity_on:
        p["hydrostatic"] = [rest_density * g / stiffness for g in pad(gravity)]
    p["cfl_number"] = cfl_number
    # particle shifting (Lind et al. 2012, shaders/sph/shifting.glsl): D = A h_s |v_i| dt, h_s = h / 2, and
    # 1 / kernel_w(dx^2), the shape of W at the spacing (kernels.glsl) for Lind's (W_ij / W(dx))^4
    p["shifting_coef"] = shifting * h / 2
    p["shifting_w"] = 1.0 / ((h * h - spacing * spacing) ** 3 if kernel == "mueller" else
                             (1 - spacing / h) ** 4 * (1 + 4 * spacing / h)) if shifting else 0.0
    return params


def _constants(text):
    """{name: (constant_id, default)} of every `layout(constant_id = k) const T NAME = v;` in `text`."""
    found = re.findall(r"constant_id\s*=\s*(\d+)\)\s*const\s+(\w+)\s+(\w+)\s*=\s*(\w+)", text)
    return {name: (int(cid), int(value) if kind == "uint" else value == "true") for cid, kind, name, value in found}


SPEC_CONSTANTS = _constants((SHADER_DIR / "sph" / "constants.glsl").read_text())
MC_SPEC_CONSTANTS = _constants((SHADER_DIR / "mc" / "constants.glsl").read_text())


def _spec_class(name, constants):
    """A namedtuple of the constants' values with `values()`: the (constant_id, uint32 value)
    pairs of a VkSpecializationInfo. A value not given is the shader's default (a constant added
    for a new feature, such as OBSTACLES, leaves the code that does not know it unchanged)."""
    def values(self):
        return [(constants[key][0], int(value)) for key, value in self._asdict().items()]

    base = namedtuple(name, list(constants), defaults=[default for _, default in constants.values()])
    return type(name, (base,), {"__slots__": (), "values": values})


Spec = _spec_class("Spec", SPEC_CONSTANTS)  # a scene's compile-time choices (shaders/sph/constants.glsl)
McSpec = _spec_class("McSpec", MC_SPEC_CONSTANTS)  # marching-cubes options (shaders/mc/constants.glsl)
DEFAULT_SPEC = Spec(**{name: default for name, (_, default) in SPEC_CONSTANTS.items()})
