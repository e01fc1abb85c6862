"""Validation against experiments: the dam break of Martin & Moyce (1952) in 2D and 3D, SPHERIC
test 2, the speed/accuracy sweep, the stability matrix and the HTML report that gathers them.

The measured series live in `validation/data/` (copied, headers and all, from the published
digitisations named in each header)."""

from sphcore.paths import DATA_DIR  # noqa: F401
