"""Surfaces: marching cubes through a HistoPyramid (seed 2), and the fluid's colour field.

`marching_cubes(volume, level, spacing, backend, method)` has scikit-image's call shape and
coordinate convention (`verts[:, a]` is the index along numpy axis a times `spacing[a]`;
normals point towards lower values; the same triangle winding), so the two can be swapped.
It runs the shaders in shaders/mc/ through Vulkan or their numba mirrors:

- "histopyramid": classify_cubes (case and vertex count per cube), reduce_cubes per level,
  write_arguments (the indirect dispatch, on the device), emit_vertices (one invocation per
  output vertex walks the pyramid down to its cube);
- "per_cube": emit_cubes, seed 2's geometry-shader baseline (a cube's vertices written where an
  atomic output counter puts them) as a GPU's subgroups run it: one invocation per run of
  `cube_run` cubes along z, one atomic per subgroup, one lane per vertex.

Both emit 3 vertices per triangle, each with a key naming its grid edge; `weld` merges the
vertices of equal keys, so each vertex is shared, as in scikit-image's output. `Extractor`
keeps buffers and pipelines for volumes of one shape (repeated extraction, benchmarks).
"""
import numpy as np

from sphcore.backends import Stage, empty_state, make_backend, neighbour_stages
from sphcore.mc.classify_cubes import classify_cubes
from sphcore.mc.emit_cubes import emit_cubes
from sphcore.mc.emit_vertices import emit_vertices
from sphcore.mc.reduce_cubes import reduce_cubes
from sphcore.mc.sample_field import sample_field
from sphcore.mc.tables import CASE_EDGES, CASE_VERTICES, CASE_WIDTH
from sphcore.mc.write_arguments import write_arguments
from sphcore.params import DEFAULT_SPEC, MC_PARAMS_DTYPE, SHADER_DIR, McSpec, kernel_coefficients, pyramid_levels
from sphcore.vk_runner import Context, VulkanError, compile_glsl
from sphcore.workgroups import group_count

METHODS = ("histopyramid", "per_cube")

# binding number = index: name -> (dtype, components, length: "samples" | "cubes" | "pyramid" |
# "capacity" | "particles" | "cells" | count)
MC_BUFFERS = {
    "volume": (np.float32, 1, "samples"),
    "cube_case": (np.uint32, 1, "cubes"),
    "cube_pyramid": (np.uint32, 1, "pyramid"),
    "arguments": (np.uint32, 1, 4),  # indirect dispatch groups (x, y, z), then the vertex total
    "vertex_position": (np.float32, 4, "capacity"),
    "vertex_normal": (np.float32, 4, "capacity"),
    "vertex_key": (np.uint32, 1, "capacity"),
    "particle_x": (np.float32, 4, "particles"),
    "particle_rho": (np.float32, 1, "particles"),
    "cell_pyramid": (np.uint32, 1, "cells"),
    "cell_start": (np.uint32, 1, "cells"),
    "case_vertices": (np.uint32, 1, 256),  # the case tables (sphcore/mc/tables.py), filled once
    "case_edges": (np.uint32, 1, 256 * CASE_WIDTH),
}

# stage -> (mirror factory, invocations: "samples" | "cubes" | "runs" | "nodes" | "one" | "indirect", buffers in order)
MC_STAGES = {
    "sample_field": (sample_field, "samples", ("volume", "particle_x", "particle_rho", "cell_pyramid",
                                               "cell_start")),
    "classify_cubes": (classify_cubes, "cubes", ("volume", "cube_case", "cube_pyramid", "case_vertices")),
    "reduce_cubes": (reduce_cubes, "nodes", ("cube_pyramid",)),
    "write_arguments": (write_arguments, "one", ("cube_pyramid", "arguments")),
    "emit_vertices": (emit_vertices, "indirect", ("volume", "cube_case", "cube_pyramid", "arguments",
                                                  "vertex_position", "vertex_normal", "vertex_key", "case_edges")),
    "emit_cubes": (emit_cubes, "runs", ("volume", "arguments", "vertex_position", "vertex_normal", "vertex_key",
                                         "case_vertices", "case_edges")),
}


def mc_parameters(shape, spacing=(1.0, 1.0, 1.0), origin=(0.0, 0.0, 0.0), isolevel=0.0, capacity=0, sph=None):
    """One record of MC_PARAMS_DTYPE for a volume of `shape`; `sph`, a record of the SPH
    parameter block, supplies the neighbour grid that sample_field reads."""
    params = np.zeros(1, MC_PARAMS_DTYPE)
    p = params[0]
    cube_total = int(np.prod([k - 1 for k in shape]))
    p["dim"] = shape
    p["cube_total"] = cube_total
    p["origin"] = origin
    p["isolevel"] = isolevel
    p["spacing"] = spacing
    p["levels"] = pyramid_levels(max(cube_total, 1))[0]
    p["capacity"] = capacity
    if sph is not None:
        for name in ("box_min", "box_max", "inv_cell", "grid_dim", "cell_total", "n", "h", "h2", "density_coef"):
            p[name] = sph[name]
    return params


RUN_FROM = 1 << 21  # cubes from which emit_cubes takes runs of 4 (default_cube_run)


def default_cube_run(shape):
    """emit_cubes' cubes per invocation for a volume of `shape`, as measured on the H200
    (benchmarks/marching_cubes.py --cube-runs): runs of 4 from RUN_FROM cubes, single cubes below."""
    return 4 if int(np.prod([k - 1 for k in shape])) >= RUN_FROM else 1


def stage_params(params, level):
    if level == 0:
        return params
    p = params.copy()
    p[0]["level"] = level
    return p


def check_shape(shape):
    """A volume shape marching cubes can take: three axes of at least 2 samples, and few enough
    samples that 4 x samples (the vertex keys) fits in 32 bits."""
    if len(shape) != 3 or min(shape) < 2:
        raise ValueError(f"marching cubes needs a 3D volume with at least 2 samples per axis, got shape {tuple(shape)}")
    if 4 * int(np.prod(shape, dtype=np.int64)) >= 2**32:
        raise ValueError(f"volume of shape {tuple(shape)} has more than 2^30 samples, the most the "
                         "32-bit vertex keys allow; extract it in blocks")


class Extractor:
    """Marching cubes over volumes of one shape, on one backend; buffers and pipelines are kept
    between calls. `extract(volume, level)` returns the triangle soup (position, normal, key),
    3 vertices per triangle; `weld` turns it into a shared-vertex mesh.

    midpoint: vertices at edge midpoints (else by linear interpolation);
    forward_normals: normals by forward differences (else central);
    cube_run: per_cube's cubes per invocation, a run along z (None: default_cube_run(shape));
    particles, cells, sph, spec: sizes and parameters for sample_field (the colour field).
    """

    def __init__(self, shape, spacing=(1.0, 1.0, 1.0), origin=(0.0, 0.0, 0.0), backend="numba",
                 method="histopyramid", midpoint=False, forward_normals=False, local_size=128, cube_run=None,
                 particles=0, cells=0, sph=None, spec=DEFAULT_SPEC, device=None, validation=None):
        check_shape(shape)
        if method not in METHODS:
            raise ValueError(f"unknown method {method!r}: choose one of {', '.join(METHODS)}")
        self.shape, self.method, self.local_size = tuple(int(k) for k in shape), method, local_size
        cube_total = int(np.prod([k - 1 for k in self.shape]))
        run = 1 if method != "per_cube" else default_cube_run(self.shape) if cube_run is None else cube_run
        if not (isinstance(run, (int, np.integer)) and run >= 1):
            raise ValueError(f"cube_run must be a positive integer (cubes per invocation), got {cube_run!r}")
        nx, ny, nz = (k - 1 for k in self.shape)
        self.sizes = {"samples": int(np.prod(self.shape)), "cubes": cube_total, "runs": nx * ny * -(-nz // int(run)),
                      "pyramid": pyramid_levels(cube_total)[1], "capacity": min(15 * cube_total, 1 << 20),
                      "particles": particles, "cells": cells}
        self.params = mc_parameters(self.shape, spacing, origin, 0.0, self.sizes["capacity"], sph)
        self.spec = spec._replace(GRID=True)
        self.mc_spec = McSpec(MIDPOINT=midpoint, FORWARD_NORMALS=forward_normals, CUBE_RUN=int(run))
        if backend not in ("numba", "vulkan"):
            raise ValueError(f"unknown backend {backend!r}: choose numba or vulkan")
        self.device = VulkanDevice(self, device, validation) if backend == "vulkan" else NumbaDevice(self)
        self.device.write("case_vertices", CASE_VERTICES)
        self.device.write("case_edges", CASE_EDGES.reshape(-1))

    def length(self, name):
        _, _, length = MC_BUFFERS[name]
        return self.sizes[length] if isinstance(length, str) else length

    def stages(self):
        """(stage, pyramid level) pairs of one extraction."""
        if self.method == "per_cube":
            return [("emit_cubes", 0)]
        levels = int(self.params[0]["levels"])
        return ([("classify_cubes", 0)] + [("reduce_cubes", level) for level in range(1, levels + 1)]
                + [("write_arguments", 0), ("emit_vertices", 0)])

    def invocations(self, stage, level):
        kind = MC_STAGES[stage][1]
        if kind == "nodes":
            size = self.sizes["cubes"]
            for _ in range(level):
                size = (size + 7) // 8
            return size
        return 1 if kind == "one" else self.sizes.get(kind)

    def extract(self, volume, level):
        """(position (V, 3), normal (V, 3), key (V,)) of the triangle soup at `level` (volume None:
        the one already on the device, from `field`); an output too small for the surface is
        enlarged and the extraction run again."""
        self.params[0]["isolevel"] = level
        if volume is not None:
            self.device.write("volume", np.ascontiguousarray(volume, np.float32).reshape(-1))
        while True:
            self.device.write("arguments", np.zeros(4, np.uint32))
            self.device.run(self.stages())
            total = int(self.device.read("arguments")[3])
            if total <= self.sizes["capacity"]:
                break
            self.resize(total)
        return (self.device.read("vertex_position", total)[:, :3], self.device.read("vertex_normal", total)[:, :3],
                self.device.read("vertex_key", total))

    def resize(self, vertices):
        """Room for `vertices` output vertices (and a quarter more)."""
        self.sizes["capacity"] = vertices + vertices // 4
        self.params[0]["capacity"] = self.sizes["capacity"]
        self.device.resize(["vertex_position", "vertex_normal", "vertex_key"])

    def field(self, particle_x, particle_rho, cell_pyramid, cell_start):
        """The colour field at every sample, from particles sorted by cell (sample_field)."""
        for name, array in (("particle_x", particle_x), ("particle_rho", particle_rho),
                            ("cell_pyramid", cell_pyramid[:self.sizes["cells"]]), ("cell_start", cell_start)):
            self.device.write(name, array)
        self.device.run([("sample_field", 0)])
        return self.device.read("volume").reshape(self.shape)

    def close(self):
        self.device.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class NumbaDevice:
    """The marching-cubes shaders' numba mirrors, on numpy buffers."""

    def __init__(self, extractor):
        self.x = extractor
        self.arrays = {name: self._empty(name) for name in MC_BUFFERS}

    def _empty(self, name):
        dtype, c, _ = MC_BUFFERS[name]
        k = self.x.length(name)
        return np.zeros((k, c) if c > 1 else k, dtype)

    def write(self, name, array):
        self.arrays[name][:len(array)] = array

    def read(self, name, count=None):
        return self.arrays[name][:count].copy()

    def resize(self, names):
        for name in names:
            self.arrays[name] = self._empty(name)

    def run(self, stages):
        x = self.x
        for stage, level in stages:
            factory, kind, buffers = MC_STAGES[stage]
            launch = factory(x.spec if stage == "sample_field" else x.mc_spec)
            args = [stage_params(x.params, level)] + [self.arrays[b] for b in buffers]
            if stage == "write_arguments":
                args.insert(1, x.local_size)  # gl_WorkGroupSize.x
            if kind == "indirect":
                groups = int(self.arrays["arguments"][0]) * int(self.arrays["arguments"][1])
            else:
                groups = group_count(x.invocations(stage, level), x.local_size)
            launch(groups, x.local_size, *args)

    def close(self):
        pass


class VulkanDevice:
    """The marching-cubes shaders through Vulkan: device-local buffers, one command buffer per
    extraction, emit_vertices dispatched indirectly from the arguments the device wrote."""

    def __init__(self, extractor, device=None, validation=None):
        self.x = extractor
        self.ctx = Context(device=device, validation=validation)
        if extractor.method == "per_cube" and not self.ctx.subgroup_operations:
            self.ctx.close()
            raise VulkanError(f"{self.ctx.device_name} lacks the subgroup operations that per_cube's emit_cubes uses "
                              "(arithmetic, ballot and shuffle in compute shaders): use method=\"histopyramid\"")
        self.buffers = {name: self._buffer(name) for name in MC_BUFFERS}
        self.pipelines = {}
        self.recordings = {}

    def _buffer(self, name):
        dtype, c, _ = MC_BUFFERS[name]
        return self.ctx.buffer(self.x.length(name) * c * np.dtype(dtype).itemsize, name)

    def _pipeline(self, stage):
        if stage not in self.pipelines:
            spirv = compile_glsl(SHADER_DIR / "mc" / f"{stage}.comp")
            pipeline = self.ctx.pipeline(spirv, len(MC_BUFFERS), MC_PARAMS_DTYPE.itemsize, self.x.local_size,
                                         self.x.spec.values() + self.x.mc_spec.values())
            pipeline.bind([self.buffers[b] for b in MC_BUFFERS])
            self.pipelines[stage] = pipeline
        return self.pipelines[stage]

    def write(self, name, array):
        self.buffers[name].write(array)

    def read(self, name, count=None):
        dtype, c, _ = MC_BUFFERS[name]
        k = self.x.length(name) if count is None else count
        return self.buffers[name].read(dtype, (k, c) if c > 1 else (k,))

    def resize(self, names):
        self.ctx.vk.vkDeviceWaitIdle(self.ctx.device)
        for name in names:
            self.buffers[name].free()
            self.buffers[name] = self._buffer(name)
        for pipeline in self.pipelines.values():
            pipeline.bind([self.buffers[b] for b in MC_BUFFERS])
        self.free_recordings()

    def record(self, stages, rec=None):
        """Record `stages` (into `rec`, else a new recording, which is returned unfinished)."""
        rec = rec or self.ctx.record()
        for stage, level in stages:
            pipeline = self._pipeline(stage)
            params = stage_params(self.x.params, level)
            if MC_STAGES[stage][1] == "indirect":
                rec.dispatch_indirect(pipeline, params, self.buffers["arguments"])
            else:
                rec.dispatch(pipeline, params, self.x.invocations(stage, level))
            rec.barrier()
        return rec

    def run(self, stages):
        key = (tuple(stages), self.x.params.tobytes())
        if key not in self.recordings:
            if len(self.recordings) >= 16:  # one per level extracted at: keep a few
                self.free_recordings()
            self.recordings[key] = self.record(stages).end()
        self.ctx.submit(self.recordings[key])

    def free_recordings(self):
        for rec in self.recordings.values():
            rec.free()
        self.recordings = {}

    def close(self):
        if self.ctx.device is None:
            return
        self.ctx.vk.vkDeviceWaitIdle(self.ctx.device)
        self.free_recordings()
        for p in self.pipelines.values():
            p.free()
        for b in self.buffers.values():
            b.free()
        self.ctx.close()


def weld(position, normal, key):
    """Shared-vertex mesh (verts, faces, normals) from a triangle soup whose vertices carry keys:
    vertices with equal keys (the same grid edge, or the same sample) become one, numbered in key
    order, so the result does not depend on the order of the soup. A triangle two of whose
    corners weld into one (possible only where a sample equals the level exactly) has no area
    and is left out, as is a vertex that only such triangles used."""
    if len(key) == 0:
        return np.zeros((0, 3), np.float32), np.zeros((0, 3), np.int32), np.zeros((0, 3), np.float32)
    order = np.argsort(key, kind="stable")  # a radix sort for 32-bit keys
    sorted_key = key[order]
    new = np.ones(len(key), bool)
    new[1:] = sorted_key[1:] != sorted_key[:-1]
    index = np.empty(len(key), np.int32)
    index[order] = np.cumsum(new, dtype=np.int32) - 1
    faces = index.reshape(-1, 3)
    verts, normals = position[order[new]], normal[order[new]]
    keep = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 2] != faces[:, 0])
    if not keep.all():
        faces = faces[keep]
        used = np.zeros(len(verts), bool)
        used[faces] = True
        renumber = np.cumsum(used, dtype=np.int32) - 1
        verts, normals, faces = verts[used], normals[used], renumber[faces]
    return verts, faces, normals


def marching_cubes(volume, level=None, spacing=(1.0, 1.0, 1.0), backend="numba", method="histopyramid",
                   midpoint=False, forward_normals=False, device=None):
    """Isosurface of a 3D array at `level`, with scikit-image's call shape and conventions:
    returns (verts (V, 3) float32, faces (F, 3) int32, normals (V, 3) float32), verts[:, a] the
    position along axis a in units of `spacing[a]`, normals towards lower values.

    level: default (min + max) / 2, as scikit-image's. Where the level lies outside the data's
    range the mesh is empty (scikit-image raises instead).
    backend: "numba" (the mirrors, on the CPU) or "vulkan"; method: "histopyramid" or "per_cube";
    midpoint: vertices at edge midpoints instead of linear interpolation; forward_normals:
    normals by forward instead of central differences.

    >>> import numpy as np, sphcore
    >>> z, y, x = np.mgrid[-1:1:24j, -1:1:24j, -1:1:24j]  # 24^3 samples, spacing 2/23
    >>> verts, faces, normals = sphcore.marching_cubes(x**2 + y**2 + z**2, level=0.5)
    >>> verts.shape[1], faces.dtype, len(faces) > 1000
    (3, dtype('int32'), True)
    >>> radius = np.linalg.norm(verts * (2 / 23) - 1, axis=1)  # the sphere of radius sqrt(0.5)
    >>> bool(abs(radius - 0.5 ** 0.5).max() < 0.01)
    True
    """
    volume = np.asarray(volume)
    check_shape(volume.shape)
    if len(spacing) != 3 or not all(np.isfinite(s) and s > 0 for s in spacing):
        raise ValueError(f"spacing must be three positive numbers, got {tuple(spacing)}")
    bad = ~np.isfinite(volume)
    if bad.any():
        raise ValueError(f"volume has {int(bad.sum())} non-finite values, the first at index "
                         f"{tuple(int(i) for i in np.argwhere(bad)[0])}")
    if level is None:
        level = 0.5 * (float(volume.min()) + float(volume.max()))
    if not np.isfinite(level):
        raise ValueError(f"level must be finite, got {level}")
    with Extractor(volume.shape, spacing, backend=backend, method=method, midpoint=midpoint,
                   forward_normals=forward_normals, device=device) as extractor:
        return weld(*extractor.extract(volume, level))


def sample_grid(position, h, spacing, box=None):
    """(origin, shape, spacing per axis) of a grid over the particles' bounding box grown by h and one
    spacing on every side, so the surface closes inside it. With walls, `box` = (box_min, box_max):
    the grid stops one sample beyond each wall, its spacing per axis is the largest at most
    `spacing` that divides the box, and its samples sit at the centres of those cells of the box,
    so that each wall lies halfway between two samples, where the surface closes (sample_field:
    the field is 0 beyond the walls, about 1 inside them with the particles' wall images)."""
    lo = position.min(axis=0) - (h + spacing)
    hi = position.max(axis=0) + (h + spacing)
    if box is None:
        shape = np.maximum(np.ceil((hi - lo) / spacing).astype(int) + 1, 2)
        return lo, tuple(int(k) for k in shape), (spacing,) * 3
    box_min, box_max = np.asarray(box[0], float), np.asarray(box[1], float)
    cells = np.maximum(np.ceil((box_max - box_min) / spacing * (1 - 1e-9)), 1).astype(int)
    step = (box_max - box_min) / cells
    # sample k at box_min + (k - 1/2) step, k = 0 .. cells + 1 (0 and cells + 1: beyond the walls)
    first = np.clip(np.floor((lo - box_min) / step + 0.5), 0, cells).astype(int)
    last = np.clip(np.ceil((hi - box_min) / step + 0.5), first + 1, cells + 1).astype(int)
    return box_min + (first - 0.5) * step, tuple(int(k) for k in last - first + 1), tuple(float(s) for s in step)


def particle_surface(scene, position, spacing=None, level=0.5, backend="numba", method="histopyramid",
                     device=None, with_field=False):
    """The fluid's surface (verts, faces, normals) in scene coordinates: the isosurface at `level` of
    the colour field sum_j m / rho_j W(x - x_j) (sample_field), sampled every `spacing`
    (default h / 2) over the particles' bounding box. The particles are sorted into the
    neighbour grid and their densities computed by the scene's own stages first. With walls the
    field counts the particles' wall images and the surface closes at the walls (sample_grid), so
    a fluid against a wall has no hole there. With `with_field`, also returns (volume, origin,
    spacing per axis).

    >>> import sphcore
    >>> scene = sphcore.Scene.from_dict({"physics": {"dimension": 3}, "fluid": {
    ...     "spacing": 0.05, "blocks": [{"min": [0.2, 0.2, 0.2], "max": [0.6, 0.6, 0.6]}]}})
    >>> verts, faces, normals = sphcore.particle_surface(scene, scene.initial_positions())
    >>> len(faces) > 0, bool(verts.min() > 0.0) and bool(verts.max() < 1.0)  # a skin around the cube
    (True, True)
    """
    if scene.dim != 3:
        raise ValueError(f"a surface needs a 3D scene; {scene['name']} is {scene.dim}D")
    position = np.asarray(position, np.float32)
    spacing = float(spacing or scene.h / 2)
    if not spacing > 0:
        raise ValueError(f"spacing must be positive, got {spacing}")
    walls = scene["domain.boundary"] == "walls"
    scene_grid = scene.config["physics"]["neighbour_search"]
    scene.config["physics"]["neighbour_search"] = "grid"  # the field reads the grid whatever the scene's search
    try:
        params, spec = scene.params(len(position)), scene.spec
    finally:
        scene.config["physics"]["neighbour_search"] = scene_grid
    state = empty_state(params, obstacles=scene["domain.obstacles"])  # the density sees their faces
    state["particle_x"][:, :3] = position
    cells = int(params[0]["cell_total"])
    # the colour field needs the positions' summation density, whatever density the scene integrates
    spec = spec._replace(CONTINUITY=False, DENSITY_DIFFUSION=0, MAX_NEIGHBOURS=0, LIST_SKIN=0)  # (and no lists)
    sorter = make_backend(backend, params, state, neighbour_stages(cells) + [Stage("compute_density")], spec,
                          **({"device": device} if backend == "vulkan" else {}))
    try:
        sorter.step(1)
        sorted_state = sorter.read()
    finally:
        sorter.close()
    box = (np.array(scene["domain.box_min"]), np.array(scene["domain.box_max"])) if walls else None
    origin, shape, spacing = sample_grid(position, scene.h, spacing, box)
    sph = params.copy()[0]  # sample_field sums poly6 (h^2 - r^2)^3: its coefficient, whatever the scene's kernel
    sph["density_coef"] = scene.mass * kernel_coefficients(scene.h, 3)["poly6"]
    with Extractor(shape, spacing, origin, backend=backend, method=method, particles=len(position),
                   cells=cells, sph=sph, spec=spec, device=device) as extractor:
        volume = extractor.field(sorted_state["particle_x"], sorted_state["particle_rho"],
                                 sorted_state["cell_pyramid"], sorted_state["cell_start"])
        mesh = weld(*extractor.extract(None, level))
    return mesh + ((volume, origin, spacing),) if with_field else mesh
