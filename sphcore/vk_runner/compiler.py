"""GLSL -> SPIR-V with glslangValidator or glslc, cached by content hash.

The cache key covers the shader, every .glsl file in the shader tree (the #include targets), the
compiler and its arguments (the preprocessor defines among them), so an edited include rebuilds
every shader that may use it and each set of defines has its own SPIR-V.
Cache folder: $SPHCORE_CACHE_DIR/spirv, else ~/.cache/sphcore/spirv. No SPIR-V is committed.

The cache is untrusted input (sphcore/cache_trust.py): an entry is read only from a folder and a file
of this user's that no one else can write, and only where its header matches its key and its bytes;
it must then look like SPIR-V (`check_spirv`). A bad entry is compiled again, with one CacheWarning,
and replaced; a folder that cannot be trusted or written costs the cache, not the run. Fresh SPIR-V
is checked by spirv-val (spirv-tools) where it is installed, before it is used or kept.
"""
import hashlib
import shutil
import subprocess
import tempfile
from pathlib import Path

from sphcore import cache_trust, paths
from sphcore.errors import ShaderCompileError


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
        return [path, "-V", "--target-env", target_env, *flags, "-I" + str(source.parent), "-o", str(output),
                str(source)]
    return [path, f"--target-env={target_env}", "-fshader-stage=compute", *flags, "-I", str(source.parent),
            "-o", str(output), str(source)]


SPIRV_MAGIC = 0x07230203


def cache_dir():
    return paths.cache_dir("spirv")


def check_spirv(code):
    """Raise cache_trust.BadEntry unless `code` looks like a SPIR-V module: whole 32-bit words, at least
    the 5-word header, the magic number 0x07230203 (little-endian, as the compilers write it here)."""
    if len(code) % 4 or len(code) < 20:
        raise cache_trust.BadEntry(f"it is not SPIR-V ({len(code)} bytes, not a whole module header of 4-byte words)")
    if int.from_bytes(code[:4], "little") != SPIRV_MAGIC:
        raise cache_trust.BadEntry("it is not SPIR-V (no magic number 0x07230203)")


def compile_glsl(source, target_env="vulkan1.1", defines=()):
    """SPIR-V bytes of the compute shader at `source`, preprocessed with `defines` ("NAME" or
    "NAME=VALUE", e.g. "SPHCORE_FLOAT64" for the float64 build: shaders/sph/real.glsl)."""
    defines = tuple(defines)
    source = Path(source).resolve()
    kind, path = find_compiler()
    digest = hashlib.sha256(cache_trust.MAGIC)  # (a new entry format: new file names, old entries unread)
    for f in [source, *sorted(source.parent.parent.rglob("*.glsl"))]:
        digest.update(str(f.relative_to(source.parent.parent)).encode() + b"\0" + f.read_bytes() + b"\0")
    digest.update(" ".join(_command(kind, path, Path("s"), Path("o"), target_env, defines)).encode())
    key = digest.hexdigest()
    folder = cache_dir()
    readable, writable = cache_trust.open_folder(folder, folder.parent, "shader cache")
    cached = folder / f"{source.stem}-{key[:24]}.spv"
    if readable:
        try:
            code = cache_trust.read_entry(cached, key)
            if code is not None:
                check_spirv(code)
                return code
        except cache_trust.BadEntry as e:
            cache_trust.warn_once(cached, f"ignored the cached SPIR-V {cached}: {e}; compiling it again")
    code = _compile(kind, path, source, target_env, defines)
    if writable:
        try:
            cache_trust.write_entry(cached, key, code)
        except OSError as e:
            cache_trust.warn_once(folder, f"cannot write to the shader cache {folder} ({e}); "
                                          f"compiled code is not kept")
    return code


def _compile(kind, path, source, target_env, defines):
    """Fresh SPIR-V of `source`, compiled in a temporary folder and checked (check_spirv, spirv-val)."""
    built = "".join(f" -D{d}" for d in defines)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "shader.spv"
        proc = subprocess.run(_command(kind, path, source, out, target_env, defines), capture_output=True, text=True)
        if proc.returncode != 0 or not out.is_file():
            message = (proc.stdout + proc.stderr).strip()
            raise ShaderCompileError(f"{kind} failed to compile {source}{built}:\n{message}")
        code = out.read_bytes()
        validator = shutil.which("spirv-val")
        check = (subprocess.run([validator, "--target-env", target_env, str(out)], capture_output=True, text=True)
                 if validator else None)
    try:
        check_spirv(code)
    except cache_trust.BadEntry as e:
        raise ShaderCompileError(f"{kind} wrote no SPIR-V for {source}{built}: {e}")
    if check is not None and check.returncode != 0:
        message = (check.stdout + check.stderr).strip()
        raise ShaderCompileError(f"spirv-val rejected what {kind} compiled from {source}{built}:\n{message}")
    return code
