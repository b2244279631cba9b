"""What every reference solver shares: its settings, input checks, the loss, cvxpy + Clarabel,
and the SLSQP / trust-constr local search of the nonconvex references.

cvxpy is imported on first use (:func:`cvxpy`): the core imports without it; scipy's optimisers
and rotations where a reference runs, so importing the lift (which imports this package for its
Python run loop) does not pay for them.
"""

from __future__ import annotations

from typing import Any, Final, Literal

import numpy as np
from numpy.typing import NDArray

from ..errors import InvalidInputError, SolverError

__all__ = [
    "TOLERANCES",
    "Loss",
    "ReferenceSolverError",
    "array",
    "check_loss",
    "clarabel_kwargs",
    "cvxpy",
    "local_minimize",
    "loss_value",
    "status_ok",
    "weights_array",
]

Loss = Literal["l1", "l2"]

#: The reference solvers' own settings (the tests' tolerances are in ``tests/tolerances.py``).
#:
#:   ``clarabel_tol``  Clarabel's tol_gap_abs / tol_gap_rel / tol_feas.
#:   ``scs_eps``       SCS eps_abs / eps_rel (first-order method: ~1e-6 relative at best).
#:   ``slsqp_ftol``    SLSQP's ftol.
#:   ``camera_xatol``  Nelder-Mead xatol (radians) of the rotation search.
#:   ``camera_fatol``  Nelder-Mead fatol of the rotation search.
#:   ``feasibility``   largest equality-constraint violation a local (SLSQP / trust-constr)
#:                     solution may have to be accepted (absolute).
TOLERANCES: Final[dict[str, float]] = {
    "clarabel_tol": 1e-9,
    "scs_eps": 1e-9,
    "slsqp_ftol": 1e-13,
    "camera_xatol": 1e-9,
    "camera_fatol": 1e-12,
    "feasibility": 1e-7,
}


class ReferenceSolverError(SolverError):
    """A reference solver did not reach an optimal (or optimal-inaccurate) status."""


def array(a: Any, shape: tuple[int | None, ...], name: str) -> NDArray[np.float64]:
    """``a`` as a finite float64 array of ``shape`` (None = any length on that axis).

    Raises
    ------
    InvalidInputError
        Wrong number of axes, a wrong length or a non-finite value.
    """
    out = np.asarray(a, dtype=np.float64)
    if out.ndim != len(shape) or any(s is not None and s != d for s, d in zip(shape, out.shape, strict=True)):
        raise InvalidInputError(f"{name} must have shape {shape}, got {out.shape}")
    if not np.all(np.isfinite(out)):
        raise InvalidInputError(f"{name} has non-finite values")
    return out


def check_loss(loss: str) -> Loss:
    """``loss`` as a :data:`Loss`; :class:`InvalidInputError` unless ``"l1"`` or ``"l2"``."""
    if loss not in ("l1", "l2"):
        raise InvalidInputError(f"loss must be 'l1' or 'l2', got {loss!r}")
    return "l1" if loss == "l1" else "l2"


def weights_array(weights: Any, n: int) -> NDArray[np.float64]:
    """Per-joint weights (n,), finite and >= 0."""
    w = array(weights, (n,), "weights")
    if np.any(w < 0):
        raise InvalidInputError("weights must be >= 0")
    return w


def loss_value(residual: NDArray[np.float64], w: NDArray[np.float64], loss: Loss) -> float:
    """``sum_j w_j loss(residual_j)`` for residuals of shape (n, 2)."""
    if loss == "l1":
        return float(np.sum(w * np.abs(residual).sum(axis=1)))
    return float(np.sum(w * (residual**2).sum(axis=1)))


def status_ok(problem: Any, name: str) -> None:
    """:class:`ReferenceSolverError` unless the cvxpy ``problem`` was solved (optimal or
    optimal-inaccurate)."""
    if problem.status not in ("optimal", "optimal_inaccurate"):
        raise ReferenceSolverError(f"{name}: solver status {problem.status!r}")


def cvxpy() -> Any:
    """cvxpy, imported lazily (typed as Any: its annotations are incomplete for mypy)."""
    import importlib

    return importlib.import_module("cvxpy")


def clarabel_kwargs() -> dict[str, Any]:
    """``problem.solve`` arguments: Clarabel at :data:`TOLERANCES` ``["clarabel_tol"]``."""
    tol = TOLERANCES["clarabel_tol"]
    return {"solver": "CLARABEL", "tol_gap_abs": tol, "tol_gap_rel": tol, "tol_feas": tol,
            "max_iter": 500}


def local_minimize(
    fun: Any, x0: NDArray[np.float64], jac: Any, constraints: list[dict[str, Any]],
    bounds: list[tuple[float | None, float | None]] | None, eq_fun: Any, name: str,
) -> NDArray[np.float64]:
    """SLSQP; if it stops without success or infeasible, SLSQP again from its own end point
    and then scipy's ``trust-constr`` (same analytic derivatives). Raises
    :class:`ReferenceSolverError` when no attempt ends feasible."""
    from scipy.optimize import Bounds, NonlinearConstraint, minimize

    feas = TOLERANCES["feasibility"]
    opts = {"ftol": TOLERANCES["slsqp_ftol"], "maxiter": 3000}
    tried: list[str] = []
    x = np.asarray(x0, dtype=np.float64)
    for _ in range(2):
        res = minimize(fun, x, jac=jac, method="SLSQP", bounds=bounds, constraints=constraints, options=opts)
        x_new = np.asarray(res.x, dtype=np.float64)
        viol = float(np.max(np.abs(eq_fun(x_new))))
        if res.success and viol <= feas:
            return x_new
        tried.append(f"SLSQP: {res.message} (violation {viol:.2e})")
        if np.all(np.isfinite(x_new)):
            x = x_new
    cons_tc = [NonlinearConstraint(c["fun"], 0.0, 0.0 if c["type"] == "eq" else np.inf, jac=c["jac"])
               for c in constraints]
    tc_bounds = None
    if bounds is not None:
        lo = np.array([-np.inf if b[0] is None else b[0] for b in bounds])
        hi = np.array([np.inf if b[1] is None else b[1] for b in bounds])
        tc_bounds = Bounds(lo, hi)
    res = minimize(fun, np.asarray(x0, dtype=np.float64), jac=jac, method="trust-constr", bounds=tc_bounds,
                   constraints=cons_tc, options={"gtol": 1e-12, "xtol": 1e-14, "maxiter": 5000})
    x_new = np.asarray(res.x, dtype=np.float64)
    viol = float(np.max(np.abs(eq_fun(x_new))))
    if viol <= feas:
        return x_new
    tried.append(f"trust-constr: {res.message} (violation {viol:.2e})")
    raise ReferenceSolverError(f"{name}: no local solver reached feasibility: " + "; ".join(tried))
