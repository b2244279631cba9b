"""The compiled steps' grouped inputs: the model's arrays and the solver's settings as two records.

:class:`ModelArrays` and :class:`StepSettings` name every field; :func:`model_record` and
:func:`settings_record` turn them into what the kernels take. With numba that is a StructRef (a
kernel unboxes it as one pointer; a named tuple of 13 arrays costs ~10 us of argument typing per
call, more than a tracked frame's camera step); without numba the named tuple itself (the kernels
then run as plain Python and read the same attributes).
"""

from __future__ import annotations

import importlib
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from .jit import HAVE_NUMBA, njit

__all__ = ["ModelArrays", "StepSettings", "model_record", "settings_record"]


class ModelArrays(NamedTuple):
    """A :class:`pose_lifter.core.model.pose_model.PoseModel` as the compiled pose step reads it, every
    array C-contiguous float64 (``k`` bases, ``r`` their rank)."""

    mean: NDArray[np.float64]  #: (36,) the mean pose
    u: NDArray[np.float64]  #: (36, r) left singular vectors of the bases
    sig: NDArray[np.float64]  #: (r,) their singular values
    vc: NDArray[np.float64]  #: (k, r) ``V``
    vt: NDArray[np.float64]  #: (r, k) ``V^T``
    comps: NDArray[np.float64]  #: (36, k) the bases
    limb_matrix: NDArray[np.float64]  #: (24, 36) the 8 limb selectors ``C_i`` stacked
    z: NDArray[np.float64]  #: (r, 24) right inverse of the limb map (``limb_coordinates``)
    n: NDArray[np.float64]  #: (r, r - 24) null-space basis of the limb map
    s0: NDArray[np.float64]  #: (r,) the reduced coordinates of zero limb vectors
    cu24_t: NDArray[np.float64]  #: (r, 24) ``(C U S)^T``
    cmu24: NDArray[np.float64]  #: (24,) ``C mu``


class StepSettings(NamedTuple):
    """The settings of a run's steps (:class:`pose_lifter.core.options.LifterOptions`), as the
    compiled run and pose step read them."""

    th: float  #: ``theta`` (0 without sparsity)
    l1: bool  #: the L1 loss (False: squared)
    limbs: bool  #: the limb-length constraints (False: the alpha-step is a linear solve)
    eta: float  #: the pose ADM's initial penalty
    eta_growth: float  #: its growth factor per iteration
    eta_max: float  #: its cap
    pose_tol: float  #: the pose ADM's relative primal/dual residual tolerance
    alpha_max_iter: int  #: Riemannian Newton steps per alpha-step
    alpha_tol: float  #: their tolerance (``newton_tol``)
    prox: float  #: the alpha-step's proximal weight (``alpha_prox``)
    cam_tol: float  #: its tolerance
    tau: float  #: its penalty
    alt_tol: float  #: a run's relative-decrease tolerance (``alternation_tol``)


if HAVE_NUMBA:  # pragma: no branch
    # numba has no type stubs: its modules imported by name, typed as Any
    _types: Any = importlib.import_module("numba.core.types")
    _structref: Any = importlib.import_module("numba.experimental.structref")

    @_structref.register
    class _ModelType(_types.StructRef):  # type: ignore[misc]
        def preprocess_fields(self, fields: Any) -> Any:
            return tuple((name, _types.unliteral(t)) for name, t in fields)

    @_structref.register
    class _SettingsType(_types.StructRef):  # type: ignore[misc]
        def preprocess_fields(self, fields: Any) -> Any:
            return tuple((name, _types.unliteral(t)) for name, t in fields)

    class _Model(_structref.StructRefProxy):  # type: ignore[misc]
        """:class:`ModelArrays` as a StructRef."""

    class _Settings(_structref.StructRefProxy):  # type: ignore[misc]
        """:class:`StepSettings` as a StructRef."""

    _structref.define_proxy(_Model, _ModelType, list(ModelArrays._fields))
    _structref.define_proxy(_Settings, _SettingsType, list(StepSettings._fields))

    @njit
    def _new_model(a: Any) -> Any:
        return _Model(a.mean, a.u, a.sig, a.vc, a.vt, a.comps, a.limb_matrix, a.z, a.n, a.s0, a.cu24_t,
                      a.cmu24)

    @njit
    def _new_settings(s: Any) -> Any:
        return _Settings(s.th, s.l1, s.limbs, s.eta, s.eta_growth, s.eta_max, s.pose_tol, s.alpha_max_iter,
                         s.alpha_tol, s.prox, s.cam_tol, s.tau, s.alt_tol)


def model_record(arrays: ModelArrays) -> ModelArrays:
    """What the kernels take for ``arrays`` (a StructRef with the same attributes under numba)."""
    arrays = ModelArrays(*(np.ascontiguousarray(a, dtype=np.float64) for a in arrays))
    return _new_model(arrays) if HAVE_NUMBA else arrays


def settings_record(settings: StepSettings) -> StepSettings:
    """What the kernels take for ``settings`` (typed: floats, ``l1`` and ``limbs`` bool, the caps
    int)."""
    s = settings
    typed = StepSettings(float(s.th), bool(s.l1), bool(s.limbs), float(s.eta), float(s.eta_growth),
                         float(s.eta_max), float(s.pose_tol), int(s.alpha_max_iter), float(s.alpha_tol),
                         float(s.prox), float(s.cam_tol), float(s.tau), float(s.alt_tol))
    return _new_settings(typed) if HAVE_NUMBA else typed
