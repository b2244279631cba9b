"""The compiled steps' settings: a run's camera, pose and alpha-step settings from the options, as
the kernels read them (:class:`pose_lifter.core.numeric.records.StepSettings`)."""

from __future__ import annotations

import functools

from ..numeric.records import StepSettings, settings_record
from ..options import LifterOptions
from .alpha.sphere_newton import RIEMANNIAN_MAX_ITER

__all__ = ["ETA_MAX", "step_settings"]

#: Cap of the pose ADM's growing penalty ``eta`` (``LifterOptions.eta_growth``).
ETA_MAX = 1e3


@functools.lru_cache(maxsize=16)
def step_settings(options: LifterOptions) -> StepSettings:
    """The settings of a run's compiled steps for ``options`` (:func:`settings_record`): the
    variant's loss, sparsity weight and limbs, the pose ADM's penalties and tolerance, the
    Riemannian alpha-step's, the camera ADM's and the run's stopping tolerance. Made once per
    options (the Python steps ask for it on every step; the record is only read)."""
    o = options
    return settings_record(StepSettings(
        th=o.theta if o.method.sparsity else 0.0, l1=o.method.loss == "l1", limbs=o.method.limbs, eta=o.eta,
        eta_growth=o.eta_growth, eta_max=ETA_MAX, pose_tol=o.pose_tol, alpha_max_iter=RIEMANNIAN_MAX_ITER,
        alpha_tol=o.newton_tol, prox=o.alpha_prox, cam_tol=o.camera_tol,
        tau=o.tau, alt_tol=o.alternation_tol))
