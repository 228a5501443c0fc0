"""fastvi: high-order Galerkin variational integrators for constrained mechanical systems.

Public API: :class:`Model`, :func:`integrate`, :class:`Result`, :class:`IntegrationError`,
:func:`integrate_ensemble`, :class:`EnsembleResult`, :class:`ModelCheckError`,
:class:`Status`, :func:`method`, :func:`sensitivity`, :func:`periodic_orbit`,
:func:`lyapunov_spectrum`, :class:`Drawing` (how :meth:`Result.animate` draws a model),
and the ready-made mechanisms in :mod:`fastvi.scenes`.
Optional: :mod:`fastvi.baselines` (RK4, SciPy), :mod:`fastvi.distributed` (Dask),
:mod:`fastvi.symbolic` (SymPy).
"""

from . import _numba  # noqa: F401  (numba settings first)
from . import scenes
from .check import ModelCheckError
from .consistent import consistent_state
from .drawing import Drawing
from .integrate import IntegrationError, Result, integrate
from .ensemble import EnsembleResult, integrate_ensemble
from .adjoint import AdjointResult, adjoint
from .fit import TrajectoryFit
from .periodic import PeriodicOrbit, PeriodicOrbitError, periodic_orbit
from .sensitivity import SensitivityResult, sensitivity, tangent_space
from .sensitivity_ensemble import EnsembleSensitivityResult, sensitivity_ensemble
from .lyapunov import LyapunovSpectrum, largest_lyapunov, lyapunov_spectrum
from .model import CALLBACK_SIGNATURE, Model
from .status import Status
from .tables import Method, method

__version__ = "0.3.0.dev0"

__all__ = [
    "Model",
    "integrate",
    "Result",
    "IntegrationError",
    "integrate_ensemble",
    "EnsembleResult",
    "ModelCheckError",
    "consistent_state",
    "Drawing",
    "sensitivity",
    "SensitivityResult",
    "sensitivity_ensemble",
    "EnsembleSensitivityResult",
    "tangent_space",
    "largest_lyapunov",
    "periodic_orbit",
    "PeriodicOrbit",
    "PeriodicOrbitError",
    "lyapunov_spectrum",
    "LyapunovSpectrum",
    "adjoint",
    "AdjointResult",
    "TrajectoryFit",
    "Status",
    "Method",
    "method",
    "scenes",
    "CALLBACK_SIGNATURE",
]
