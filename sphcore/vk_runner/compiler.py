"""GLSL -> SPIR-V with glslangValidator or glslc, cached by content hash.

The cache key covers the shader, every .glsl file in the shader tree (the #include targets), the
compiler and its arguments (the preprocessor defines among them), so an edited include rebuilds
every shader that may use it and each set of defines has its own SPIR-V.
Cache folder: $SPHCORE_CACHE_DIR, else ~/.cache/sphcore/spirv. No SPIR-V is committed.
"""
import hashlib
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

from sphcore import paths


class ShaderCompileError(RuntimeError):
    """No compiler, or the compiler rejected a shader (its message names file and line)."""


INSTALL_HINT = ("no GLSL compiler found: install glslangValidator or glslc "
                "(Debian/Ubuntu: apt-get install glslang-tools, or apt-get install glslc)")


def find_compiler():
    """(kind, path) of the first compiler on PATH, or raise ShaderCompileError."""
    for kind in ("glslangValidator", "glslc"):
        path = shutil.which(kind)
        if path:
            return kind, path
    raise ShaderCompileError(INSTALL_HINT)


def _command(kind, path, source, output, target_env, defines=()):
    flags = [f"-D{d}" for d in defines]  # the same spelling for both compilers: -DNAME or -DNAME=VALUE
    if kind == "glslangValidator":
        return [path, "-V", f"--target-env", target_env, *flags, "-I" + str(source.parent), "-o", str(output),
                str(source)]
    return [path, f"--target-env={target_env}", "-fshader-stage=compute", *flags, "-I", str(source.parent),
            "-o", str(output), str(source)]


def cache_dir():
    return paths.cache_dir("spirv")


def compile_glsl(source, target_env="vulkan1.1", defines=()):
    """SPIR-V bytes of the compute shader at `source`, preprocessed with `defines` ("NAME" or
    "NAME=VALUE", e.g. "SPHCORE_FLOAT64" for the float64 build: shaders/sph/real.glsl)."""
    defines = tuple(defines)
    source = Path(source).resolve()
    kind, path = find_compiler()
    digest = hashlib.sha256()
    for f in [source, *sorted(source.parent.parent.rglob("*.glsl"))]:
        digest.update(str(f.relative_to(source.parent.parent)).encode() + b"\0" + f.read_bytes() + b"\0")
    digest.update(" ".join(_command(kind, path, Path("s"), Path("o"), target_env, defines)).encode())
    cached = cache_dir() / f"{source.stem}-{digest.hexdigest()[:24]}.spv"
    if cached.is_file():
        return cached.read_bytes()
    cached.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "shader.spv"
        proc = subprocess.run(_command(kind, path, source, out, target_env, defines), capture_output=True, text=True)
        if proc.returncode != 0 or not out.is_file():
            message = (proc.stdout + proc.stderr).strip()
            built = "".join(f" -D{d}" for d in defines)
            raise ShaderCompileError(f"{kind} failed to compile {source}{built}:\n{message}")
        code = out.read_bytes()
    tmp_name = cached.with_suffix(f".tmp{os.getpid()}")
    tmp_name.write_bytes(code)
    os.replace(tmp_name, cached)
    return code
