"""The two ways to run the shaders: their numba mirrors (default) and Vulkan.

Both execute the same plan, an ordered list of stages (`plan`), over the same buffers bound
at the same binding numbers (`BUFFERS`), with the same parameter bytes.
"""
import numpy as np

from sphcore.params import SHADER_DIR
from sphcore.sph.compute_density import compute_density
from sphcore.sph.compute_forces import compute_forces
from sphcore.sph.integrate import integrate
from sphcore.workgroups import group_count

# binding number = index; dtype and components per particle
BUFFERS = {
    "particle_x": (np.float32, 2),
    "particle_v": (np.float32, 2),
    "particle_a": (np.float32, 2),
    "particle_rho": (np.float32, 1),
    "particle_p": (np.float32, 1),
}

# stage -> (numba launcher, buffers its shader binds, in binding order)
STAGES = {
    "compute_density": (compute_density, ("particle_x", "particle_rho", "particle_p")),
    "compute_forces": (compute_forces, ("particle_x", "particle_v", "particle_a", "particle_rho", "particle_p")),
    "integrate": (integrate, ("particle_x", "particle_v", "particle_a")),
}


def plan(scene):
    """The ordered stages one time step of `scene` runs; both backends execute this list."""
    return ["compute_density", "compute_forces", "integrate"]


def empty_state(n):
    return {name: np.zeros((n, c) if c > 1 else n, dtype) for name, (dtype, c) in BUFFERS.items()}


class NumbaBackend:
    """The shaders' numba mirrors on the CPU: work groups in parallel, invocations in order."""

    name = "numba"

    def __init__(self, params, state, stages, local_size=128):
        self.params, self.stages, self.local_size = params, stages, local_size
        self.state = {k: np.array(v, copy=True) for k, v in state.items()}
        self.n_groups = group_count(int(params[0]["n"]), local_size)

    def run_stage(self, stage):
        launch, names = STAGES[stage]
        launch(self.n_groups, self.local_size, self.params, *(self.state[k] for k in names))

    def step(self, count=1):
        for _ in range(count):
            for stage in self.stages:
                self.run_stage(stage)

    def read(self):
        return {k: v.copy() for k, v in self.state.items()}

    def close(self):
        pass


class VulkanBackend:
    """The shaders through Vulkan: device-local buffers, many steps per command buffer."""

    name = "vulkan"

    def __init__(self, params, state, stages, local_size=128, device=None, validation=None,
                 steps_per_submit=64):
        from vk_runner import Context, compile_glsl
        self.ctx = Context(device=device, validation=validation)
        self.params, self.stages, self.steps_per_submit = params, stages, steps_per_submit
        self.n = int(params[0]["n"])
        self.buffers = {}
        for name, (dtype, c) in BUFFERS.items():
            self.buffers[name] = self.ctx.buffer(self.n * c * np.dtype(dtype).itemsize, name)
            self.buffers[name].write(state[name])
        all_buffers = [self.buffers[name] for name in BUFFERS]
        self.pipelines = {}
        for stage in set(stages):
            spirv = compile_glsl(SHADER_DIR / "sph" / f"{stage}.comp")
            pipeline = self.ctx.pipeline(spirv, len(BUFFERS), params.dtype.itemsize, local_size)
            pipeline.bind(all_buffers)
            self.pipelines[stage] = pipeline
        self._recordings = {}

    def _recording(self, steps, stages):
        key = (steps, tuple(stages))
        if key not in self._recordings:
            rec = self.ctx.record()
            for _ in range(steps):
                for stage in stages:
                    rec.dispatch(self.pipelines[stage], self.params, self.n)
                    rec.barrier()
            self._recordings[key] = rec.end()
        return self._recordings[key]

    def run_stage(self, stage):
        self.ctx.submit(self._recording(1, [stage]))

    def step(self, count=1):
        full, rest = divmod(count, self.steps_per_submit)
        for _ in range(full):
            self.ctx.submit(self._recording(self.steps_per_submit, self.stages))
        if rest:
            self.ctx.submit(self._recording(rest, self.stages))

    def read(self):
        return {name: self.buffers[name].read(dtype, (self.n, c) if c > 1 else (self.n,))
                for name, (dtype, c) in BUFFERS.items()}

    def close(self):
        if self.ctx.device is None:
            return
        self.ctx.vk.vkDeviceWaitIdle(self.ctx.device)
        for rec in self._recordings.values():
            rec.free()
        for p in self.pipelines.values():
            p.free()
        for b in self.buffers.values():
            b.free()
        self.ctx.close()


BACKENDS = {"numba": NumbaBackend, "vulkan": VulkanBackend}


def make_backend(name, params, state, stages, **options):
    if name not in BACKENDS:
        raise ValueError(f"unknown backend {name!r}: choose one of {', '.join(BACKENDS)}")
    return BACKENDS[name](params, state, stages, **options)
