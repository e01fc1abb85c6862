"""Marching cubes: numba mirrors of shaders/mc/*.comp and the generated case tables."""
