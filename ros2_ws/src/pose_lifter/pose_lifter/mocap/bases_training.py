"""Learning the pose bases from CMU mocap (``pose-lifter learn-bases``): the trials of a split, their
poses normalised, and sparse, PCA or class-wise PCA bases of them
(:mod:`pose_lifter.core.model.bases`).
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any, Final

import numpy as np

__all__ = ["CMU_ACKNOWLEDGEMENT", "learn_bases"]

#: The acknowledgement the CMU database asks for, recorded in every basis file learned from it.
CMU_ACKNOWLEDGEMENT: Final[str] = (
    "The data used in this project was obtained from mocap.cs.cmu.edu. The database was "
    "created with funding from NSF EIA-0196217.")


def learn_bases(
    method: str = "sparse", n_bases: int | None = None, data_dir: str | Path | None = None, step: int = 8,
    sparsity: float = 0.1, n_starts: int = 30, n_per_class: int = 6, seed: int = 0, n_iter: int = 2000,
    command: str = "", split: str = "paper", limb_spread: float = 0.0,
) -> Any:
    """Learn bases from the CMU trials of ``split``.

    ``split="paper"``: the paper's training split (MANIFEST ``paper_split == train``, subject
    01's playground), for the paper's mode and experiments. ``split="prior"``: the trials the
    packaged learned prior was fitted on (its metadata ``training_trials``: the training split
    minus the prior's validation trials, so tuning on those stays held out), for the hybrid mode.

    Every ``step``-th frame of the 120 Hz trials is used (8 -> 15 Hz: consecutive frames are
    nearly identical). With ``limb_spread`` > 0 every frame's limbs are first scaled by factors
    drawn per frame (:func:`pose_lifter.mocap.views.limb_scale_factors`, upper arm, forearm, thigh and
    shin uniform in ``1 +- limb_spread``, both sides alike; seeded by ``seed``), so the bases
    represent people of other proportions than the CMU subjects. Then every pose is normalised
    with :func:`pose_lifter.core.model.skeleton.normalise_pose`. Class-wise PCA uses the trials as
    classes.

    Returns
    -------
    PoseBases
    """
    from pose_lifter.core.model.bases import learn_classwise_pca_bases, learn_pca_bases, learn_sparse_bases
    from pose_lifter.core.model.skeleton import normalise_pose
    from pose_lifter.mocap import cmu as mocap

    d = mocap.resolve_data_dir(data_dir)
    if split == "paper":
        trials = sorted({t.trial for t in mocap.read_manifest(d) if t.paper_split == "train"})
    elif split == "prior":
        from pose_lifter.core.model.prior import PosePrior

        trials = sorted(str(t) for t in PosePrior.load().metadata.get("training_trials", []))
        outside = set(trials) - set(mocap.split_trials("train", d))
        if outside:  # a prior file trained on held-out motion must not spread to the bases
            raise mocap.MocapDataError(f"the prior's training trials include {sorted(outside)}, "
                                       "outside the training split")
    else:
        raise ValueError(f"split must be 'paper' or 'prior', got {split!r}")
    if not trials:
        raise mocap.MocapDataError(f"no training trials for split {split!r} in {d}")
    rng = np.random.default_rng(seed)
    clips = []
    for t in trials:
        world = mocap.load_trial(t, d, step=step)
        if limb_spread > 0:
            from pose_lifter.mocap.views import limb_scale_factors, scale_limbs

            world = scale_limbs(world, limb_scale_factors(len(world), limb_spread, rng))
        clips.append(normalise_pose(world))
    poses = np.concatenate(clips)
    labels = np.concatenate([np.full(len(c), t) for c, t in zip(clips, trials, strict=True)])
    meta = {
        "command": command, "training_trials": trials, "frame_step": step, "source_fps": 120,
        "split": split, "limb_spread": limb_spread,
        "data": "CMU Graphics Lab Motion Capture Database, " + CMU_ACKNOWLEDGEMENT,
        "normalisation": "pose_lifter.core.model.skeleton.normalise_pose (centroid, body frame, "
                         "right lower leg = 1)",
    }
    with warnings.catch_warnings():
        # the lasso of the cluster-centre codes reports slow convergence on tiny duality gaps
        warnings.filterwarnings("ignore", message="Objective did not converge")
        if method == "sparse":
            return learn_sparse_bases(poses, n_bases=n_bases or 200, sparsity=sparsity, n_starts=n_starts,
                                      seed=seed, n_iter=n_iter, metadata=meta)
        if method == "pca":
            return learn_pca_bases(poses, n_bases=n_bases or 30, n_starts=n_starts, seed=seed, metadata=meta)
        if method == "classwise-pca":
            return learn_classwise_pca_bases(poses, labels, n_per_class=n_per_class, n_starts=n_starts,
                                             seed=seed, metadata=meta)
    raise ValueError(f"unknown method {method!r}")
