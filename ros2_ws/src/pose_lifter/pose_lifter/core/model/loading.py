"""The data a lifter solves with, loaded from files and derived once per setting.

:class:`LifterData` holds the pose bases and, on first use, the pose-step model of their limb
targets and the learned priors: each is loaded or built again only when the option that names it
(``limb_proportions``, ``prior_file``, ``temporal_prior_file``) changes, so that a lifter whose
other options change keeps them; and the temporal prior's partner for bodies the image cuts
(``NAME_crop.npz`` beside it, :func:`cut_partner`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import PriorFileError
from ..options import LimbProportions, Mode
from .bases import PoseBases, default_bases_path
from .pose_model import PoseModel
from .prior import (
    DEFAULT_CUT_PRIOR_PATH,
    DEFAULT_OFFLINE_CUT_PRIOR_PATH,
    DEFAULT_OFFLINE_PRIOR_PATH,
    DEFAULT_TEMPORAL_PRIOR_PATH,
    PosePrior,
)
from .skeleton import ANTHROPOMETRIC_PROPORTIONS

__all__ = ["LifterData", "cut_partner"]


class LifterData:
    """The bases, the pose-step model and the learned priors of a lifter.

    Parameters
    ----------
    bases : PoseBases
    prior, temporal_prior : PosePrior or None
        Priors given in memory: used as long as the file option they stand for keeps the value
        it had here (``prior_file``, ``temporal_prior_file``), then loaded from the file named.
    prior_file, temporal_prior_file : str
        The file options the given priors stand for.
    """

    def __init__(self, bases: PoseBases, prior: PosePrior | None = None,
                 temporal_prior: PosePrior | None = None, prior_file: str = "",
                 temporal_prior_file: str = "") -> None:
        self.bases = bases
        self._prior = prior
        self._prior_key: str | None = None if prior is None else prior_file
        self._temporal = temporal_prior
        self._temporal_key: str | None = None if temporal_prior is None else temporal_prior_file
        self._temporal_given = temporal_prior is not None  # stands for its file option's value
        self._model: PoseModel | None = None
        self._model_key: str | None = None
        self._cut: dict[tuple[str, bool], PosePrior] = {}  # the cut bodies' priors, by file
        mp = bases.mean_pose
        #: the RMS spread of the mean pose's image positions (the lifter's input normalisation)
        self.mean_spread = float(np.sqrt(np.mean(np.sum((mp[:, :2] - mp[:, :2].mean(0)) ** 2, axis=1))))

    @classmethod
    def packaged(cls, mode: Mode, prior: PosePrior | None = None, temporal_prior: PosePrior | None = None,
                 prior_file: str = "", temporal_prior_file: str = "") -> LifterData:
        """The packaged bases of ``mode`` (:func:`pose_lifter.core.model.bases.default_bases_path`)."""
        return cls(PoseBases.load(default_bases_path(mode)), prior, temporal_prior, prior_file,
                   temporal_prior_file)

    def model(self, limb_proportions: LimbProportions) -> PoseModel:
        """The pose-step model of the bases with the limb targets ``limb_proportions`` names
        (``"bases"``: the training mean's; ``"anthropometric"``)."""
        if self._model is None or self._model_key != limb_proportions:
            props = self.bases.limb_proportions if limb_proportions == "bases" else ANTHROPOMETRIC_PROPORTIONS
            self._model = PoseModel.build(self.bases, props)
            self._model_key = limb_proportions
        return self._model

    def prior(self, path: str) -> PosePrior:
        """The learned prior of ``path`` (``""``: the packaged one)."""
        if self._prior is None or self._prior_key != path:
            self._prior = _causal(PosePrior.load(path or None), path)
            self._prior_key = path
        return self._prior

    def temporal_prior(self, path: str, reads_ahead: bool = False) -> PosePrior:
        """The temporal prior of ``path``: causal, or with ``reads_ahead`` (a lift that knows each
        track's next frames) one that may read frames after the one it lifts
        (:attr:`PosePrior.future_frames`). ``""``: the packaged one, with ``reads_ahead`` the
        packaged offline prior (:data:`~pose_lifter.core.model.prior.DEFAULT_OFFLINE_PRIOR_PATH`)."""
        key = path or ("offline" if reads_ahead else "")
        kept = self._temporal_key == (path if self._temporal_given else key)
        if self._temporal is None or not kept:
            default = DEFAULT_OFFLINE_PRIOR_PATH if reads_ahead else DEFAULT_TEMPORAL_PRIOR_PATH
            self._temporal = PosePrior.load(path or default)
            self._temporal_key, self._temporal_given = key, False
        if not reads_ahead:
            _causal(self._temporal, path)
        return self._temporal

    def cut_body_prior(self, path: str, reads_ahead: bool) -> PosePrior | None:
        """The prior of a tracked frame whose 2D lacks a shoulder
        (:class:`~pose_lifter.core.lift.hybrid.PriorFit`): the temporal prior's partner trained
        with bodies cut by the image's borders, the file of its name with ``_crop`` before the
        suffix (:func:`cut_partner`): of the packaged temporal prior (``path`` ``""``: causal, or
        with ``reads_ahead`` the offline one), or of the file ``path`` names when it exists;
        otherwise None, and None for a temporal prior given in memory."""
        if self._temporal_given:
            return None
        if path:
            partner = cut_partner(Path(path))
        else:
            partner = DEFAULT_OFFLINE_CUT_PRIOR_PATH if reads_ahead else DEFAULT_CUT_PRIOR_PATH
        if not partner.is_file():
            return None
        key = (str(partner), reads_ahead)
        if key not in self._cut:
            prior = PosePrior.load(partner)
            self._cut[key] = prior if reads_ahead else _causal(prior, str(partner))
        return self._cut[key]


def cut_partner(path: Path) -> Path:
    """The file of a temporal prior's partner for bodies the image cuts: ``NAME_crop.npz`` beside
    ``NAME.npz``."""
    return path.with_name(f"{path.stem}_crop{path.suffix}")


def _causal(prior: PosePrior, path: str) -> PosePrior:
    """``prior`` if it predicts the last frame of its window; a prior trained to read frames after
    the one it lifts (``tools/train_prior.py --future``) cannot run on a live track."""
    if prior.future_frames:
        raise PriorFileError(f"{path or 'the packaged prior'}: a prior of the frame {prior.future_frames} "
                             "before its window's last, which needs each track's next frames: only an "
                             "offline lift (pose-lifter lift) reads it")
    return prior
