"""Compiled kernels: dense linear algebra, one step, and the time loops.

Nothing here sees a Python object: a model is a tuple of cfuncs plus arrays, a method is a
tuple of arrays. Failures are integer status codes (see :mod:`fastvi.status`).
"""
