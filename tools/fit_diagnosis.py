"""Why the hybrid fit corrects the learned prior as much (or as little) as it does: per-frame
oracle tests on tracked sequences (the node's per-track policy), as ``tools/accuracy.py`` films
them.

    .venv/bin/python tools/fit_diagnosis.py --trials 02_04 02_05 ... [--frames 60]
        [--azimuths 0 90 180 270] [--distance 6] [--condition clean] [--set NAME=VALUE ...]
        [--prior PATH --temporal-prior PATH --bases PATH]

Per tracked frame (hybrid, defaults unless ``--set``) it records the fit's own pose (before the
track's output smoothing), the published one and its prior's 3D error and prints:

* errors (P-MPJPE, MPJPE after centring and the true leg's scale, jitter = mean 3D acceleration
  error, all mm) of the fit, of the prior's pose inside the fit (temporal prior on tracked
  frames), and of the prior's pose in the fit's limb lengths;
* representation: the truth's residual (mm) from the bases' span (the coefficients of
  :meth:`Runs.start_alpha`, a pseudo-inverse), and its limb proportions against the model's and
  the track's;
* objective vs solver: the same frame's hybrid objective fitted from the truth's pose (same
  prior rows, same iteration caps, and run to convergence) against the fit's: where the truth's
  start ends lower, the solver misses it; where it ends higher, the objective prefers the fit;
* how often the outlier pass drops a visible joint, the start kept (prior / mirrored / pass),
  and the share of jitter on frames where the kept start changes.
"""

from __future__ import annotations

import argparse
import os
import sys
import warnings
from pathlib import Path
from typing import Any, NamedTuple

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np
from numpy.typing import NDArray

sys.path.insert(0, str(Path(__file__).resolve().parent))
from accuracy import CENTRE, FOCAL, _parse
from pose_lifter.core import Lifter, LifterOptions, PoseBases, p_mpjpe
from pose_lifter.core.lift import hybrid as hybrid_mod
from pose_lifter.core.model.bases import default_bases_path
from pose_lifter.core.model.metrics import procrustes_align
from pose_lifter.core.model.skeleton import RIGHT_LOWER_LEG, limb_lengths, normalise_pose_flat
from pose_lifter.core.results import StartKind
from pose_lifter.core.track.policy import TrackPolicy
from pose_lifter.mocap.cmu import load_trial
from pose_lifter.mocap.scenes import corrupt_2d
from pose_lifter.mocap.views import film, view_rotation

CAPTURE: dict[str, Any] = {}
#: The saved ``start`` column: a cold start's index, or a negative code for the other kinds.
START_CODES = {StartKind.WARM: -1, StartKind.MIRRORED: -2, StartKind.PRIOR: -3, StartKind.LEARNED: -4}


def _wrapped(orig: Any) -> Any:
    def starts_people(fit: Any, people: Any) -> Any:
        out = yield from orig(fit, people)  # a solve: its calls pass through
        p = people[-1]  # this tool lifts one person at a time
        CAPTURE["fit"] = fit
        CAPTURE["person"] = p
        CAPTURE["args"] = (p.x, p.xn, p.w, p.norm, p.warm, p.cam0, p.track)
        CAPTURE["out"] = out[-1]
        return out
    return starts_people


def _oracle(lifter: Lifter, truth_c: NDArray[np.float64], scale_px: float) -> dict[str, float]:
    """The truth's start under the frame's captured prior rows: objectives at the default caps and
    at convergence, and their errors."""
    _, xn, _, norm, _, cam0, _ = CAPTURE["args"]
    w_after = CAPTURE["out"].weights
    prior, _ = lifter.runs.solve(CAPTURE["fit"].rows_steps(CAPTURE["person"], w_after))
    # the truth in the normalised frame: its image positions there, depth at the same scale
    target = np.empty((12, 3))
    target[:, :2] = xn
    s = scale_px / norm.spread
    target[:, 2] = s * (truth_c[:, 2] - truth_c[:, 2].mean())
    a_true = lifter.runs.start_alpha(target)
    o = lifter.options
    r_caps = lifter.runs.run(xn, w_after, a_true, cam0, o.hybrid_alternations, prior=prior)
    r_conv = lifter.runs.run(xn, w_after, a_true, cam0, 20, prior=prior, pose_max_iter=200)
    best = CAPTURE["out"].best().run
    r_fit_conv = lifter.runs.run(xn, w_after, best.pose.alpha, best.camera.camera, 20, prior=prior,
                                 pose_max_iter=200)
    th = o.theta
    for k, r in (("fit", best), ("truthconv", r_conv)):
        cam = r.camera.camera
        y = r.pose.pose
        proj = cam.project(y)
        out_terms = {"2d": float(w_after @ np.abs(xn - proj).sum(axis=1)),
                     "sparse": th * float(np.abs(r.pose.alpha).sum()),
                     "pxy": float(prior.weights[:, 0] @ np.abs(prior.target[:, :2] - proj).sum(axis=1)),
                     "pz": prior.depth_term(y, cam.projection)}
        for kk, vv in out_terms.items():
            CAPTURE.setdefault("terms", {})[f"T_{k}_{kk}"] = vv
    out = {"F_fit": best.objective, "F_truth_caps": r_caps.objective, "F_truth_conv": r_conv.objective,
           "F_fit_conv": r_fit_conv.objective}
    for k, r in (("truth_caps", r_caps), ("truth_conv", r_conv), ("fit_conv", r_fit_conv)):
        cam = r.camera.camera
        pc = (r.pose.pose - r.pose.pose.mean(0)) @ cam.rotation.T
        out["e_" + k] = float(p_mpjpe(pc, truth_c / truth_c_leg(truth_c)))
    return out


def truth_c_leg(truth_c: NDArray[np.float64]) -> float:
    return float(limb_lengths(truth_c)[RIGHT_LOWER_LEG])


def _parser() -> argparse.ArgumentParser:
    """The command line (the module docstring)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", nargs="+", required=True)
    ap.add_argument("--data", default=None)
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--azimuths", type=float, nargs="+", default=[0.0, 90.0, 180.0, 270.0])
    ap.add_argument("--distance", type=float, default=6.0)
    ap.add_argument("--condition", default="clean", choices=("clean", "noise0.1", "outliers20"))
    ap.add_argument("--set", action="append", default=[])
    ap.add_argument("--bases", default=None)
    ap.add_argument("--oracle", action="store_true", help="also the truth-start runs (slower)")
    ap.add_argument("--save", type=Path, default=None, help="write the sequences (fit, prior, truth) here")
    ap.add_argument("--true-limbs", action="store_true",
                    help="an oracle: the track's limb constraints take the truth's proportions")
    return ap


def _diagnosed_lifter(args: argparse.Namespace, opts: LifterOptions) -> Lifter:
    """The lifter of ``opts`` (hybrid bases unless ``--bases``), warmed up, every hybrid fit's starts
    recorded in :data:`CAPTURE`; with ``--true-limbs`` every track takes the truth's limb
    proportions (``CAPTURE["true_props"]``)."""
    lifter = Lifter(PoseBases.load(args.bases or default_bases_path("hybrid")), opts)
    lifter.warm_up()
    hybrid_mod.PriorFit.starts_people = _wrapped(hybrid_mod.PriorFit.starts_people)  # type: ignore[method-assign]
    if args.true_limbs:
        from pose_lifter.core.track import state as track_mod
        def true_props(self: Any, image: bool = False) -> Any:
            return CAPTURE["true_props"]
        track_mod.Track.limb_proportions = true_props  # type: ignore[method-assign]
    return lifter


class _View(NamedTuple):
    """One trial filmed from one azimuth: ``px`` (n, 12, 2) pixels and ``conf`` (n, 12) after the
    condition's corruption, ``truth`` (n, 12, 3) the camera-frame poses centred (metres) and
    ``leg_m`` (n,) the right lower leg's length (metres)."""

    px: NDArray[np.float64]
    conf: NDArray[np.float64]
    truth: NDArray[np.float64]
    leg_m: NDArray[np.float64]


def _film_view(world: NDArray[np.float64], az: float, args: argparse.Namespace, rng: np.random.Generator
               ) -> _View:
    """The trial ``world`` (n, 12, 3) filmed at azimuth ``az`` (degrees) and ``--distance``, its 2D
    corrupted as ``--condition`` says (random numbers from ``rng``)."""
    n = len(world)
    rots = np.repeat(view_rotation(az, 0.0)[None], n, axis=0)
    pts, cam_pose, leg = film(world, rots, np.full(n, args.distance), np.ones(n, dtype=bool))
    spec = {"clean": {}, "noise0.1": {"noise": 0.1},
            "outliers20": {"outliers": 0.2}}[args.condition]
    px, conf = corrupt_2d(FOCAL * pts + CENTRE, FOCAL * leg, spec.get("noise", 0.0),
                          spec.get("outliers", 0.0), 0.0, rng)
    leg_m = limb_lengths(world)[:, RIGHT_LOWER_LEG]
    truth = cam_pose - cam_pose.mean(axis=1, keepdims=True)
    return _View(px, conf, truth, leg_m)


def _representation(lifter: Lifter, truth_i: NDArray[np.float64], leg: float) -> dict[str, float]:
    """The truth's (12, 3) residual from the bases' span (mm; body frame, leg = 1, scaled by ``leg``
    metres) and its limb proportions' (log) error against the model's and the track's."""
    row: dict[str, float] = {}
    body, ok = normalise_pose_flat(np.ascontiguousarray(truth_i))
    if ok:
        a = lifter.runs.start_alpha(truth_i)
        rec = lifter.bases.pose(a).reshape(-1)
        res = np.linalg.norm((rec - body).reshape(12, 3), axis=1)
        row["repr_mm"] = 1000 * leg * float(res.mean())
    tl_ = np.log(limb_lengths(truth_i))
    ml_ = np.log(np.sqrt(lifter.model.limb_sq))
    row["limb_model_err"] = float(np.abs((tl_ - tl_.mean()) - (ml_ - ml_.mean())).mean())
    if CAPTURE.get("args") and CAPTURE["args"][6].limb_proportions is not None:
        rad = CAPTURE["fit"].limb_radii(CAPTURE["args"][6].limb_proportions)
        if rad is not None:
            rl_ = np.log(rad)
            row["limb_track_err"] = float(np.abs((tl_ - tl_.mean()) - (rl_ - rl_.mean())).mean())
    return row


def _prior_input(truth_i: NDArray[np.float64]) -> dict[str, float]:
    """The captured prior's disagreement with its own input (normalised units) and the error of its
    depths under the image's positions against the truth (12, 3), when the frame was fitted."""
    row: dict[str, float] = {}
    if "args" in CAPTURE:
        xc, _, wc, normc = CAPTURE["args"][:4]
        pp_in = CAPTURE["out"].prior_pose
        vis_c = wc > 0
        trivial = pp_in.copy()
        trivial[vis_c, :2] = xc[vis_c]  # the prior's depths under the image's positions
        trivial -= trivial.mean(axis=0)
        row["e_prior_xy2d"] = 1000 * float(p_mpjpe(trivial, truth_i))
        row["prior_xy_resid"] = float(np.linalg.norm(pp_in[vis_c, :2] - xc[vis_c], axis=1).mean()
                                      / normc.spread)
    return row


def _lift_view(lifter: Lifter, opts: LifterOptions, args: argparse.Namespace, view: _View
               ) -> tuple[list[dict[str, float]], NDArray[np.float64], NDArray[np.float64], NDArray[np.int_]]:
    """Lift the view as one track and measure every frame.

    Returns
    -------
    rows : list of dict
        One per frame: its errors and diagnostics (module docstring).
    fit, prior : ndarray, shape (n, 12, 3)
        The fit's own poses and its prior's poses in the fit (each in the true leg's metres).
    starts : ndarray, shape (n,)
        The kept start per frame (:data:`START_CODES`).
    """
    truth, leg_m = view.truth, view.leg_m
    n = len(view.px)
    policy = TrackPolicy(lifter, track_timeout=1e9)
    fit = np.full((n, 12, 3), np.nan)
    pri = np.full((n, 12, 3), np.nan)
    starts = np.zeros(n, dtype=int)
    rows: list[dict[str, float]] = []
    for i in range(n):
        CAPTURE.clear()
        CAPTURE["true_props"] = Lifter.limb_proportions_of(truth[i])
        tl = policy.lift(0, i * 33_333_333, view.px[i], view.conf[i])
        r = tl.result
        # the fit's own pose (the published one is smoothed over the track's frames)
        own = tl.fit_pose_camera if tl.fit_pose_camera is not None else r.pose_camera
        fit[i] = own * leg_m[i]
        out_m = 1000 * float(p_mpjpe(r.pose_camera * leg_m[i], truth[i]))
        pp = r.prior_pose - r.prior_pose.mean(0)
        pp = pp / limb_lengths(pp)[RIGHT_LOWER_LEG]  # the prior's pose, its right shin = 1
        pri[i] = pp * leg_m[i]
        starts[i] = START_CODES.get(r.start, r.start_index)
        vis = view.conf[i] >= opts.confidence_threshold
        row = {"e_fit": 1000 * float(p_mpjpe(fit[i], truth[i])),
               "e_prior": 1000 * float(p_mpjpe(pri[i], truth[i])),
               "m_fit": 1000 * float(np.linalg.norm(fit[i] - truth[i], axis=1).mean()),
               "m_prior": 1000 * float(np.linalg.norm(pri[i] - truth[i], axis=1).mean()),
               "e_published": out_m,
               "dropped": float(np.count_nonzero(vis & (r.weights == 0))),
               "start": float(starts[i]), "warm": float(tl.warm_started),
               "reinit": float(tl.reinitialised)}
        row.update(_representation(lifter, truth[i], leg_m[i]))
        row.update(_prior_input(truth[i]))
        if args.oracle and "args" in CAPTURE and tl.warm_started:
            o = _oracle(lifter, truth[i], FOCAL * 1.0 / args.distance)
            o = {kk: (1000 * leg_m[i] * vv if kk.startswith("e_") else vv) for kk, vv in o.items()}
            row.update(o)
            row.update(CAPTURE.get("terms", {}))
        rows.append(row)
    return rows, fit, pri, starts


def _add_jitter(jit: dict[str, list[Any]], fit: NDArray[np.float64], pri: NDArray[np.float64],
                truth: NDArray[np.float64], starts: NDArray[np.int_]) -> None:
    """Add one view's jitter (mm per frame^2: 3D acceleration errors) and per-joint errors to
    ``jit``: of the fit and of the prior (n, 12, 3 each) against the truth (n, 12, 3), after a
    per-frame similarity alignment too, and the fit's on the frames around a change of the kept
    start (``starts`` (n,)) and elsewhere."""
    ap_ = fit[2:] - 2 * fit[1:-1] + fit[:-2]
    pp_ = pri[2:] - 2 * pri[1:-1] + pri[:-2]
    at = truth[2:] - 2 * truth[1:-1] + truth[:-2]
    jf = 1000 * np.linalg.norm(ap_ - at, axis=-1).mean(axis=-1)
    jp = 1000 * np.linalg.norm(pp_ - at, axis=-1).mean(axis=-1)
    jit["fit"] += jf.tolist()
    for key, d in (("per_joint_fit", ap_ - at), ("per_joint_prior", pp_ - at),
                   ("per_joint_err_fit", fit - truth), ("per_joint_err_prior", pri - truth)):
        jit.setdefault(key, []).append(1000 * np.linalg.norm(d, axis=-1).mean(axis=0))
    fa, pa = procrustes_align(fit, truth), procrustes_align(pri, truth)
    jit.setdefault("fit_aligned", []).extend((1000 * np.linalg.norm(
        fa[2:] - 2 * fa[1:-1] + fa[:-2] - at, axis=-1).mean(axis=-1)).tolist())
    jit.setdefault("prior_aligned", []).extend((1000 * np.linalg.norm(
        pa[2:] - 2 * pa[1:-1] + pa[:-2] - at, axis=-1).mean(axis=-1)).tolist())
    jit["prior"] += jp.tolist()
    sw = (starts[2:] != starts[1:-1]) | (starts[1:-1] != starts[:-2])
    jit["switch"] += jf[sw].tolist()
    jit["steady"] += jf[~sw].tolist()


def _print_means(rows: list[dict[str, float]], jit: dict[str, list[Any]], settings: dict[str, Any]) -> None:
    """Every measure's mean over the frames, the jitter and the per-joint errors."""
    keys = sorted({k for r in rows for k in r})
    mean = {k: float(np.nanmean([r.get(k, np.nan) for r in rows])) for k in keys}
    print(f"{len(rows)} frames; settings {settings}")
    for k in keys:
        print(f"  {k:16s} {mean[k]:.4f}")
    print(f"  jitter fit {np.mean(jit['fit']):.1f}, prior-in-fit {np.mean(jit['prior']):.1f} mm/frame^2; "
          "on frames around a change of kept start "
          f"{np.mean(jit['switch']) if jit['switch'] else np.nan:.1f} "
          f"({len(jit['switch'])} frames), else {np.mean(jit['steady']):.1f}")
    print(f"  jitter after per-frame similarity alignment: fit {np.mean(jit['fit_aligned']):.1f}, "
          f"prior {np.mean(jit['prior_aligned']):.1f}")
    for k in ("per_joint_fit", "per_joint_prior", "per_joint_err_fit", "per_joint_err_prior"):
        print(f"  {k:20s}", np.round(np.mean(jit[k], axis=0), 1).tolist())


def _print_breakdowns(rows: list[dict[str, float]], oracle: bool) -> None:
    """The errors by quartile of the prior's residual from its input, the kept starts and (with
    ``--oracle``) how often the truth's start ends below the fit's objective."""
    pr_ = np.array([r.get("prior_xy_resid", np.nan) for r in rows])
    ep_ = np.array([r["e_prior"] for r in rows])
    ef_ = np.array([r["e_fit"] for r in rows])
    ok_ = np.isfinite(pr_)
    if ok_.any():
        q = np.quantile(pr_[ok_], [0.25, 0.5, 0.75])
        bins = np.digitize(pr_, q)
        print(f"  prior's xy residual quartiles {np.round(q, 3).tolist()}; corr with prior error "
              f"{np.corrcoef(pr_[ok_], ep_[ok_])[0, 1]:.2f}")
        for b in range(4):
            sel = ok_ & (bins == b)
            print(f"    quartile {b + 1}: prior {ep_[sel].mean():.1f} mm, fit {ef_[sel].mean():.1f} mm")
    st = np.array([r["start"] for r in rows])
    print("  kept start:", {int(s): int(np.count_nonzero(st == s)) for s in np.unique(st)})
    if oracle:
        ff = np.array([r.get("F_fit", np.nan) for r in rows])
        ft = np.array([r.get("F_truth_conv", np.nan) for r in rows])
        fc = np.array([r.get("F_fit_conv", np.nan) for r in rows])
        ok = np.isfinite(ft)
        print(f"  truth start converged below the fit's objective on {np.mean(ft[ok] < ff[ok]):.2f} of "
              f"frames, below the fit continued to convergence on {np.mean(ft[ok] < fc[ok]):.2f}")


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    warnings.simplefilter("ignore")
    settings = _parse(args.set)
    opts = LifterOptions().replace(**settings)
    lifter = _diagnosed_lifter(args, opts)
    rows: list[dict[str, float]] = []
    seqs: list[tuple[NDArray[np.float64], ...]] = []
    jit: dict[str, list[Any]] = {"fit": [], "prior": [], "switch": [], "steady": []}
    for k, t in enumerate(args.trials):
        world = load_trial(t, args.data, step=4, max_frames=args.frames)
        for v, az in enumerate(args.azimuths):
            view = _film_view(world, az, args, np.random.default_rng(1000 * k + v))
            view_rows, fit, pri, starts = _lift_view(lifter, opts, args, view)
            rows += view_rows
            seqs.append((fit.copy(), pri.copy(), view.truth.copy()))
            _add_jitter(jit, fit, pri, view.truth, starts)
    if args.save is not None:
        np.savez(args.save, **{f"{k}_{i}": a for i, sq in enumerate(seqs)
                              for k, a in zip(("fit", "prior", "truth"), sq, strict=True)})
    _print_means(rows, jit, settings)
    _print_breakdowns(rows, args.oracle)
    return 0


if __name__ == "__main__":
    sys.exit(main())
