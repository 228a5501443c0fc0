"""Set-up and compile cost of fastvi in one fresh process (docs/benchmarks.md).

Run it twice from a fresh clone: the first process compiles the kernels and the user's
callbacks (cold), the second loads both from numba's on-disk cache (warm)::

    python docs/decisions/scripts/setup_times.py; python docs/decisions/scripts/setup_times.py
"""
import sys, time
t0 = time.perf_counter()
import numpy as np
import fastvi
import os
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import setup_model as u  # noqa: E402  (an importable user model: disk-cacheable)
t_import = time.perf_counter() - t0

def make():
    return fastvi.Model(2, 1, params=[9.81], mass=np.eye(2), potential=u.V, potential_grad=u.dV,
                        constraint=u.g, constraint_jacobian=u.G, name="pendulum")

q0, v0 = np.array([1.0, 0.0]), np.array([0.0, 0.0])
a = time.perf_counter(); m1 = make(); m1.kernel_arguments(); t_model1 = time.perf_counter() - a
a = time.perf_counter(); r1 = fastvi.integrate(m1, q0, v0, h=0.01, n_steps=2000); t_int1 = time.perf_counter() - a
a = time.perf_counter(); m2 = make(); m2.kernel_arguments(); t_model2 = time.perf_counter() - a
a = time.perf_counter(); r2 = fastvi.integrate(m2, q0, v0, h=0.01, n_steps=2000); t_int2 = time.perf_counter() - a
Q0 = np.tile(q0, (64, 1)); V0 = np.zeros((64, 2)); V0[:, 1] = np.linspace(0, 1, 64)
a = time.perf_counter(); e1 = fastvi.integrate_ensemble(m2, Q0, V0, h=0.01, n_steps=2000); t_ens1 = time.perf_counter() - a
a = time.perf_counter(); e2 = fastvi.integrate_ensemble(m2, Q0, V0, h=0.01, n_steps=2000); t_ens2 = time.perf_counter() - a
print(f"import {t_import:.2f} | Model#1 callbacks {t_model1:.3f} | integrate#1 {t_int1:.2f} | "
      f"Model#2 callbacks {t_model2:.3f} | integrate#2 {t_int2:.3f} | ensemble#1 {t_ens1:.2f} | ensemble#2 {t_ens2:.3f}")
for name, r in (("integrate#1", r1), ("integrate#2", r2), ("ensemble#1", e1), ("ensemble#2", e2)):
    print(f"  {name}: {r.summary().splitlines()[0]}")
