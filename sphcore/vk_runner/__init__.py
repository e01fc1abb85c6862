"""Run GLSL compute shaders through Vulkan (the `vulkan` PyPI package).

`Context` chooses a device (a discrete GPU where there is one, else lavapipe on the CPU),
holds device-local buffers and compute pipelines, and records many dispatches into one
command buffer. `compile_glsl` builds SPIR-V with glslangValidator or glslc, cached by
content hash. Every failure a user can meet raises `VulkanError` with the fix in its message.
"""
from sphcore.vk_runner.compiler import ShaderCompileError, compile_glsl
from sphcore.vk_runner.context import Context, VulkanError

__all__ = ["Context", "VulkanError", "ShaderCompileError", "compile_glsl"]
