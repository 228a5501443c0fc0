"""A user's model in an importable module (a pendulum in Cartesian coordinates)."""
import numpy as np

def V(q, p):
    return p[0] * q[1]

def dV(q, p, out):
    out[0] = 0.0
    out[1] = p[0]

def g(q, p, out):
    out[0] = 0.5 * (q[0] * q[0] + q[1] * q[1] - 1.0)

def G(q, p, out):
    out[0, 0] = q[0]
    out[0, 1] = q[1]
