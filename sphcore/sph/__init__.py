"""numba mirrors of shaders/sph/*.comp, one module per shader with the same stem."""
