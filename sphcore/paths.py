"""Where the shaders, the shipped scenes and the measured data live.

Installed from a wheel they are inside the package (pyproject.toml maps `shaders/`, `scenes/`
and `validation/data/` to `sphcore/shaders`, `sphcore/scenes` and `sphcore/data`, so nothing
but `sphcore` lands at the top of site-packages); in a source checkout (or an editable install)
they are the repository's own folders beside `sphcore/`.
"""
import os
from pathlib import Path

PACKAGE_DIR = Path(__file__).resolve().parent


def _find(installed, checkout):
    inside = PACKAGE_DIR / installed
    return inside if inside.is_dir() else PACKAGE_DIR.parent / checkout


SHADER_DIR = _find("shaders", "shaders")
SCENE_DIR = _find("scenes", "scenes")
DATA_DIR = _find("data", "validation/data")


def cache_dir(kind, root=None):
    """The folder of one kind of compiled output ("spirv", "numba") under `root`, else
    $SPHCORE_CACHE_DIR, else ~/.cache/sphcore. Deleting it is always safe: it is rebuilt."""
    return Path(root or os.environ.get("SPHCORE_CACHE_DIR") or Path.home() / ".cache" / "sphcore") / kind
