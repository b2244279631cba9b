"""Training of the learned 2D -> 3D prior (:class:`pose_lifter.core.model.prior.PosePrior`).

Data: mocap poses of the training split (:func:`pose_lifter.mocap.cmu.split_trials`), re-filmed for
every sample with a fresh random view and person (augmentation):

* azimuth uniform in [0, 360) degrees, elevation uniform in [-30, 45], camera roll N(0, 5);
* perspective at 2.5-10 m (half the samples; the packaged priors: 1.5-10 m, ``make prior``'s
  ``--aug 'distance=(1.5,10.0)'``) or weak perspective;
* limb lengths changed per person by up to +-20 % (:func:`pose_lifter.mocap.views.scale_limbs`);
* Gaussian 2D noise (std up to 0.15 right-lower-leg lengths), missing joints (up to 20 %,
  visibility 0) and confident outliers (up to 25 % of joints displaced by 1-3 leg lengths,
  visibility kept at 1) (:func:`pose_lifter.mocap.scenes.corrupt_2d`).

Pose augmentations on top (:data:`GENERALISE`, the packaged priors' recipe): mirrored people,
arms or legs transplanted from another frame, limbs turned about their joints, and the lower body
out of the image (:mod:`pose_lifter.mocap.pose_augment`); for the cut bodies' variants
(``*_crop.npz``, ``make prior-temporal-cut`` and ``prior-offline-cut``) also a person close to the
camera, cut at both ends by the image's borders (``p_crop``, off by default).

Models: :func:`train_prior_residual` (the packaged priors: a residual MLP, Martinez et al. 2017,
in PyTorch, the optional extra ``train``; batch normalisation folded into the linear layers) and
:func:`train_prior` (scikit-learn's ``MLPRegressor``: ReLU, Adam, squared loss on standardised
targets, ``partial_fit`` epoch by epoch). Both train on freshly augmented samples each epoch, the
step size decayed geometrically, and return a :class:`PosePrior` (pure-numpy inference). The
per-output mean absolute error on held-out training-split trials is the prior's uncertainty.
Deterministic for a seed (one BLAS / torch thread).
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from pose_lifter.core.model.metrics import p_mpjpe
from pose_lifter.core.model.prior import FRAME_DIM, OUT_DIM, PosePrior, prior_features
from pose_lifter.core.model.skeleton import HIPS, LIMBS, N_JOINTS, RIGHT_LOWER_LEG
from pose_lifter.mocap.detector_model import LOWER_LEG_JOINTS, autoregressive, joint_spreads
from pose_lifter.mocap.pose_augment import mirror_poses, random_turns, transplant_limbs, turn_limbs
from pose_lifter.mocap.scenes import corrupt_2d
from pose_lifter.mocap.views import limb_scale_factors, scale_limbs, view_rotations

if TYPE_CHECKING:
    import torch
    from torch import nn

__all__ = ["GENERALISE", "Augmentation", "TrainingBatch", "augment_poses", "detector_noise", "make_batch",
           "train_prior", "train_prior_residual"]


@dataclass(frozen=True)
class Augmentation:
    """Ranges of the random views and corruptions (see the module docstring)."""

    elevation: tuple[float, float] = (-30.0, 45.0)
    roll_std: float = 5.0
    distance: tuple[float, float] = (2.5, 10.0)
    p_perspective: float = 0.5
    limb_spread: float = 0.2
    p_noise: float = 0.7
    noise_max: float = 0.15
    p_missing: float = 0.5
    missing_max: float = 0.2
    p_outliers: float = 0.25
    outliers_max: float = 0.25
    min_visible: int = 6
    chunk: int = 64
    #: pose augmentations (:mod:`pose_lifter.mocap.pose_augment`), per sample (a window shares them):
    #: the mirrored person, arms or legs of another frame, limbs turned about their joints
    p_mirror: float = 0.0
    p_transplant: float = 0.0
    p_turn: float = 0.0
    turn_root_deg: float = 40.0
    turn_end_deg: float = 30.0
    p_turn_limb: float = 0.5
    #: the lower body out of the image: knees and ankles missing (and the hips too on a third of
    #: those samples), every frame of the window
    p_lower_cut: float = 0.0
    #: a person close to the camera, cut by the image's top and bottom borders: the joints of the
    #: window above one image row and below another missing, the two rows cutting up to
    #: ``crop_max`` of the target frame's image height each off its top and its bottom
    p_crop: float = 0.0
    crop_max: float = 0.4
    #: of the noisy chunks, this share gets a detector's noise instead of white noise: per joint
    #: scaled like the COCO sigmas and, over a window's frames, correlated (first-order
    #: autoregressive, correlation uniform in ``detector_correlation``;
    #: :mod:`pose_lifter.mocap.detector_model`)
    p_detector: float = 0.0
    detector_correlation: tuple[float, float] = (0.0, 0.9)


#: The augmentation that generalises past the training motions (the cross-action folds,
#: ``tools/cross_action.py``): mirrored people, limb transplants and turned limbs on top of the
#: views and corruptions.
GENERALISE: Augmentation = Augmentation(p_mirror=0.5, p_transplant=0.3, p_turn=0.5, p_lower_cut=0.1)


@dataclass(frozen=True)
class TrainingBatch:
    """Augmented samples: ``features`` (N, 36 w), ``targets`` (N, 36) in the prior's output
    units, and what made them (``camera_pose`` (N, 12, 3) metres, ``scale`` (N,) metres per
    output unit)."""

    features: NDArray[np.float64]
    targets: NDArray[np.float64]
    camera_pose: NDArray[np.float64]
    scale: NDArray[np.float64]


def make_batch(sequences: Sequence[NDArray[np.float64]], n: int, rng: np.random.Generator,
               aug: Augmentation = Augmentation(), window: int = 1, future: int = 0) -> TrainingBatch:
    """``n`` augmented samples from random frames (windows of ``window`` consecutive frames) of
    ``sequences`` (each (F, 12, 3), metres, Y-up). The target is the window's frame
    ``window - 1 - future``: the last one (a causal prior), or with ``future > 0`` one that has
    ``future`` frames after it in the window (an offline prior that reads past and future). The
    window is centred on the target frame's centroid and its input normalised on that frame
    (:func:`~pose_lifter.core.model.prior.prior_features`), the target expressed in that
    normalisation."""
    if not 0 <= future < window:
        raise ValueError(f"future must be in [0, window), got {future} for a window of {window}")
    lens = np.array([len(s) for s in sequences])
    ok = lens >= window
    if not np.any(ok):
        raise ValueError(f"no sequence has {window} frames")
    prob = np.where(ok, lens - window + 1, 0).astype(np.float64)
    seq_idx = rng.choice(len(sequences), size=n, p=prob / prob.sum())
    frames = np.empty((n, window, N_JOINTS, 3))
    for i, s in enumerate(seq_idx):
        f = rng.integers(0, lens[s] - window + 1)
        frames[i] = sequences[s][f:f + window]
    frames = augment_poses(frames, sequences, prob, rng, aug)
    factors = limb_scale_factors(n, aug.limb_spread, rng)
    frames = scale_limbs(frames.reshape(n * window, N_JOINTS, 3), np.repeat(factors, window, axis=0))
    az = rng.uniform(0.0, 360.0, n)
    el = rng.uniform(*aug.elevation, n)
    ro = np.clip(rng.normal(0.0, aug.roll_std, n), -3 * aug.roll_std, 3 * aug.roll_std)
    rots = view_rotations(az, el, ro)
    dist = rng.uniform(*aug.distance, n)
    persp = rng.random(n) < aug.p_perspective
    # the window's frames share a camera; each is centred on the target frame's centroid
    target = window - 1 - future
    cur = frames.reshape(n, window, N_JOINTS, 3)
    centroid = cur[:, target].mean(axis=1)
    rel = cur - centroid[:, None, None, :]
    cam = np.einsum("nab,nwjb->nwja", rots, rel)
    depth = np.where(persp[:, None, None], cam[..., 2] + dist[:, None, None], dist[:, None, None])
    pts = cam[..., :2] / np.maximum(depth, 0.05)[..., None]
    knee, ankle = LIMBS[RIGHT_LOWER_LEG]  # the noise unit: the leg at the centroid's depth
    leg = np.linalg.norm(cur[:, target, knee] - cur[:, target, ankle], axis=-1) / dist
    vis = np.ones((n, window, N_JOINTS), dtype=bool)
    for lo in range(0, n, aug.chunk):
        hi = min(lo + aug.chunk, n)
        noise = rng.uniform(0.0, aug.noise_max) if rng.random() < aug.p_noise else 0.0
        outl = rng.uniform(0.02, aug.outliers_max) if rng.random() < aug.p_outliers else 0.0
        miss = rng.uniform(0.0, aug.missing_max) if rng.random() < aug.p_missing else 0.0
        sub = pts[lo:hi]
        if noise > 0 and aug.p_detector > 0 and rng.random() < aug.p_detector:
            sub = sub + detector_noise(sub.shape[:2], noise, rng.uniform(*aug.detector_correlation), rng
                                       ) * leg[lo:hi, None, None, None]
            noise = 0.0
        noisy, _ = corrupt_2d(sub, np.broadcast_to(leg[lo:hi, None], sub.shape[:2]), noise, outl, 0.0, rng)
        pts[lo:hi] = noisy
        if miss > 0:
            vis[lo:hi] = rng.random(sub.shape[:3]) >= miss
    if aug.p_lower_cut > 0:
        cut = rng.random(n) < aug.p_lower_cut
        hips = cut & (rng.random(n) < 1.0 / 3.0)
        vis[np.ix_(cut, np.arange(window), LOWER_LEG_JOINTS)] = False
        vis[np.ix_(hips, np.arange(window), np.array(HIPS))] = False
    if aug.p_crop > 0:
        vis &= ~_cropped(pts, target, rng.random(n) < aug.p_crop, aug.crop_max, rng)
    # keep at least min_visible joints in the target frame
    short = vis[:, target].sum(axis=1) < aug.min_visible
    vis[short, target] = True
    feats, centre, radius = prior_features(pts, vis, window, target)
    cur_cam = cam[:, target]
    scale = radius * dist  # metres per output unit
    tgt = np.empty((n, N_JOINTS, 3))
    tgt[..., :2] = (cur_cam[..., :2] / dist[:, None, None] - centre[:, None, :]) / radius[:, None, None]
    tgt[..., 2] = cur_cam[..., 2] / dist[:, None] / radius[:, None]
    return TrainingBatch(feats, tgt.reshape(n, 3 * N_JOINTS), cur_cam, scale)


def _cropped(pts: NDArray[np.float64], target: int, crop: NDArray[np.bool_], crop_max: float,
             rng: np.random.Generator) -> NDArray[np.bool_]:
    """The joints (N, W, 12) of the windows ``pts`` (N, W, 12, 2) outside an image that the
    ``crop`` samples' borders cut: rows drawn uniformly within ``crop_max`` of the target frame's
    image height from its top and its bottom, the same for every frame of the window."""
    y = pts[..., 1]
    lo, hi = y[:, target].min(axis=1), y[:, target].max(axis=1)
    height = hi - lo
    top = lo + rng.uniform(0.0, crop_max, len(y)) * height
    bottom = hi - rng.uniform(0.0, crop_max, len(y)) * height
    out = (y < top[:, None, None]) | (y > bottom[:, None, None])
    return np.asarray(out & crop[:, None, None])


def detector_noise(shape: tuple[int, ...], noise: float, correlation: float, rng: np.random.Generator
                   ) -> NDArray[np.float64]:
    """A detector's 2D error (``shape`` + (12, 2), leg lengths) of samples (N, W): per joint the
    standard deviation :func:`pose_lifter.mocap.detector_model.joint_spreads` of ``noise``, over
    the W frames of a window a first-order autoregressive process of that ``correlation``
    (stationary: every frame has the same spread)."""
    n, window = shape
    err = autoregressive(rng.standard_normal((n, window, N_JOINTS, 2)), correlation, axis=1)
    return err * joint_spreads(noise)[None, None, :, None]


def augment_poses(frames: NDArray[np.float64], sequences: Sequence[NDArray[np.float64]],
                  prob: NDArray[np.float64], rng: np.random.Generator, aug: Augmentation
                  ) -> NDArray[np.float64]:
    """The pose augmentations of ``aug`` on sampled windows ``frames`` (N, W, 12, 3): mirrored
    (``p_mirror``), both arms or both legs from a random window of ``sequences`` (drawn with
    weights ``prob``, ``p_transplant``), limbs turned (``p_turn``); the frames of a window
    share each change. No random numbers are drawn for an augmentation whose probability is 0."""
    n, window = frames.shape[:2]
    out = frames
    if aug.p_mirror > 0:
        m = np.asarray(rng.random(n) < aug.p_mirror)
        out = np.where(m[:, None, None, None], mirror_poses(out), out)
    if aug.p_transplant > 0:
        t = rng.random(n) < aug.p_transplant
        rows = np.flatnonzero(t)
        if len(rows):
            lens = np.array([len(s) for s in sequences])
            donors = np.empty((len(rows), window, N_JOINTS, 3))
            for i, s in enumerate(rng.choice(len(sequences), size=len(rows), p=prob / prob.sum())):
                f = rng.integers(0, lens[s] - window + 1)
                donors[i] = sequences[s][f:f + window]
            legs = rng.random(len(rows)) < 0.5
            limbs = np.zeros((len(rows), 4), dtype=bool)
            limbs[:, :2] = ~legs[:, None]
            limbs[:, 2:] = legs[:, None]
            moved = transplant_limbs(out[rows].reshape(-1, N_JOINTS, 3), donors.reshape(-1, N_JOINTS, 3),
                                     np.repeat(limbs, window, axis=0))
            out = out.copy()
            out[rows] = moved.reshape(len(rows), window, N_JOINTS, 3)
    if aug.p_turn > 0:
        u = np.flatnonzero(rng.random(n) < aug.p_turn)
        if len(u):
            root, end = random_turns(len(u), aug.turn_root_deg, aug.turn_end_deg, aug.p_turn_limb, rng)
            moved = turn_limbs(out[u].reshape(-1, N_JOINTS, 3), np.repeat(root, window, axis=0),
                               np.repeat(end, window, axis=0))
            out = out.copy()
            out[u] = moved.reshape(len(u), window, N_JOINTS, 3)
    return out


def _evaluate(prior: PosePrior, batch: TrainingBatch) -> tuple[float, NDArray[np.float64]]:
    """(mean P-MPJPE in mm, per-output mean absolute error (12, 3)) of ``prior`` on ``batch``."""
    pred = prior.forward(batch.features)
    err = np.abs(pred - batch.targets.reshape(-1, N_JOINTS, 3)).mean(axis=0)
    metres = pred * batch.scale[:, None, None]
    truth = batch.camera_pose
    mm = 1000.0 * float(np.mean(p_mpjpe(metres, truth)))
    return mm, err


class _Start(NamedTuple):
    """What a training starts from.

    Attributes
    ----------
    val : TrainingBatch
        The validation samples (a generator of their own, seeded ``seed + 1``).
    first : TrainingBatch
        The first epoch's samples.
    out_mean, out_scale : ndarray, shape (36,)
        The standardisation of the outputs, from ``first``'s targets.
    """

    val: TrainingBatch
    first: TrainingBatch
    out_mean: NDArray[np.float64]
    out_scale: NDArray[np.float64]


def _start(train: Sequence[NDArray[np.float64]], validation: Sequence[NDArray[np.float64]],
           samples_per_epoch: int, rng: np.random.Generator, seed: int, aug: Augmentation, window: int,
           future: int) -> _Start:
    """The validation batch, the first epoch's batch (drawn from ``rng``) and the output
    standardisation of a training on the sequences ``train`` and ``validation`` (each (F, 12, 3))."""
    val = make_batch(validation, min(20_000, samples_per_epoch), np.random.default_rng(seed + 1), aug,
                     window, future)
    first = make_batch(train, samples_per_epoch, rng, aug, window, future)
    out_mean = first.targets.mean(axis=0)
    out_scale = first.targets.std(axis=0) + 1e-6
    return _Start(val, first, out_mean, out_scale)


def train_prior(train: Sequence[NDArray[np.float64]], validation: Sequence[NDArray[np.float64]], *,
                hidden: tuple[int, ...] = (768, 768), epochs: int = 30, samples_per_epoch: int = 100_000,
                lr: float = 1e-3, lr_final: float = 5e-5, batch_size: int = 512, l2: float = 1e-5,
                window: int = 1, seed: int = 0, aug: Augmentation = Augmentation(),
                log: Callable[[str], None] | None = print, future: int = 0) -> PosePrior:
    """Fit the prior by minimising the mean squared error of its standardised outputs
    (``MLPRegressor`` loss ``1/2 mean ||(y - m)/s - f(x)||^2 + l2/2 ||W||^2``) over freshly
    augmented samples of ``train``; ``validation`` (held-out trials) gives the uncertainty
    ``abs_error`` and the printed figures.

    Parameters
    ----------
    train, validation : sequences of ndarray, shape (F, 12, 3)
        Mocap sequences in metres (Y-up), at the node's frame rate for ``window > 1``.
    hidden : tuple of int
        Hidden layer widths.
    epochs, samples_per_epoch : int
        ``partial_fit`` passes, each over a new augmented set.
    lr, lr_final : float
        Adam step size of the first and the last epoch (geometric decay).
    window : int
        Frames per input (causal temporal variant for ``window > 1``).
    future : int
        Frames of the window after the one whose pose is the target (0: causal; > 0: an offline
        prior, which the lifter refuses, :class:`~pose_lifter.core.model.loading.LifterData`).
    seed : int

    Returns
    -------
    PosePrior
    """
    from sklearn.neural_network import MLPRegressor

    rng = np.random.default_rng(seed)
    val, first, out_mean, out_scale = _start(train, validation, samples_per_epoch, rng, seed, aug, window,
                                             future)
    reg = MLPRegressor(hidden_layer_sizes=hidden, activation="relu", solver="adam", alpha=l2,
                       batch_size=batch_size, learning_rate_init=lr, random_state=seed, shuffle=True)
    decay = (lr_final / lr) ** (1.0 / max(1, epochs - 1))
    t0 = time.perf_counter()
    batch = first
    prior: PosePrior | None = None
    for ep in range(epochs):
        if ep > 0:
            batch = make_batch(train, samples_per_epoch, rng, aug, window, future)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            reg.partial_fit(batch.features, (batch.targets - out_mean) / out_scale)
        opt = getattr(reg, "_optimizer", None)  # Adam's step size, decayed per epoch
        if opt is not None and hasattr(opt, "learning_rate_init"):
            opt.learning_rate_init = lr * decay ** (ep + 1)
        prior = PosePrior(tuple(np.asarray(w, dtype=np.float64) for w in reg.coefs_),
                          tuple(np.asarray(b, dtype=np.float64) for b in reg.intercepts_),
                          out_mean, out_scale, np.ones((N_JOINTS, 3)), window)
        if log is not None and (ep % 5 == 4 or ep == epochs - 1):
            mm, _ = _evaluate(prior, val)
            log(f"epoch {ep + 1}/{epochs}: loss {reg.loss_:.4f}, validation P-MPJPE {mm:.1f} mm, "
                f"{time.perf_counter() - t0:.0f} s")
    assert prior is not None
    mm, err = _evaluate(prior, val)
    meta = {"validation_p_mpjpe_mm": round(mm, 2), "hidden": list(hidden), "epochs": epochs,
            "samples_per_epoch": samples_per_epoch, "seed": seed, "lr": lr, "lr_final": lr_final,
            "l2": l2, "batch_size": batch_size, "augmentation": aug.__dict__, "future_frames": future,
            "train_seconds": round(time.perf_counter() - t0, 1)}
    return PosePrior(prior.weights, prior.biases, out_mean, out_scale, np.maximum(err, 1e-6), window, meta)


@dataclass(frozen=True)
class _ResidualNet:
    """The residual network of :func:`train_prior_residual` (torch modules).

    Attributes
    ----------
    stem : torch.nn.Sequential
        ``Linear -> BatchNorm -> ReLU -> Dropout``, (N, 36 w) -> (N, width).
    body : torch.nn.ModuleList
        The residual blocks, two such layers each, (N, width) -> (N, width).
    head : torch.nn.Linear
        (N, width) -> (N, 36).
    modules : torch.nn.ModuleList
        All three, for their parameters and their training mode.
    """

    stem: nn.Sequential
    body: nn.ModuleList
    head: nn.Linear
    modules: nn.ModuleList

    @staticmethod
    def build(n_in: int, width: int, blocks: int, dropout: float) -> _ResidualNet:
        """A new network of ``n_in`` inputs, initialised from torch's global generator (stem,
        blocks, head, in this order)."""
        from torch import nn

        def layer(a: int, b: int) -> list[nn.Module]:
            return [nn.Linear(a, b), nn.BatchNorm1d(b), nn.ReLU(), nn.Dropout(dropout)]

        stem = nn.Sequential(*layer(n_in, width))
        body = nn.ModuleList([nn.Sequential(*layer(width, width), *layer(width, width))
                              for _ in range(blocks)])
        head = nn.Linear(width, OUT_DIM)
        return _ResidualNet(stem, body, head, nn.ModuleList([stem, body, head]))

    def __call__(self, x: torch.Tensor) -> torch.Tensor:
        """The network's output (N, 36) for the inputs ``x`` (N, 36 w), torch tensors."""
        h = self.stem(x)
        for blk in self.body:
            h = h + blk(h)
        out: torch.Tensor = self.head(h)
        return out


def _residual_epoch(net: _ResidualNet, opt: torch.optim.Optimizer, gen: torch.Generator, batch: TrainingBatch,
                    start: _Start, batch_size: int) -> float:
    """One training epoch of ``net`` over ``batch`` in the random order of the torch generator
    ``gen``: the whole mini-batches of ``batch_size`` samples, their targets standardised by
    ``start``. Returns the mean squared error over the epoch's samples."""
    import torch

    x = torch.from_numpy(batch.features.astype(np.float32))
    y = torch.from_numpy(((batch.targets - start.out_mean) / start.out_scale).astype(np.float32))
    net.modules.train()
    order = torch.randperm(len(x), generator=gen)
    total = 0.0
    for lo in range(0, len(x) - batch_size + 1, batch_size):
        idx = order[lo:lo + batch_size]
        opt.zero_grad(set_to_none=True)
        loss = torch.mean((net(x[idx]) - y[idx]) ** 2)
        loss.backward()
        opt.step()
        total += float(loss.detach()) * batch_size
    return total / max(1, (len(x) // batch_size) * batch_size)


def train_prior_residual(train: Sequence[NDArray[np.float64]], validation: Sequence[NDArray[np.float64]], *,
                         width: int = 512, blocks: int = 2, dropout: float = 0.25, epochs: int = 30,
                         samples_per_epoch: int = 100_000, lr: tuple[float, float] = (1e-3, 5e-5),
                         batch_size: int = 256, weight_decay: float = 1e-5, window: int = 1, seed: int = 0,
                         aug: Augmentation = Augmentation(), log: Callable[[str], None] | None = print,
                         future: int = 0) -> PosePrior:
    """Fit a residual prior (Martinez et al. 2017) in PyTorch (the optional extra ``train``).

    The network: ``Linear -> BatchNorm -> ReLU -> Dropout`` to ``width`` units, ``blocks``
    residual blocks of two such layers (their output added to their input), a linear output.
    Minimises the mean squared error of the standardised outputs ``mean ||(y - m)/s - f(x)||^2``
    with Adam (decoupled weight decay ``weight_decay``, step size decayed geometrically from
    ``lr[0]`` to ``lr[1]`` over the epochs) on freshly augmented samples of ``train`` per epoch
    (as :func:`train_prior`). The batch normalisation (running statistics) is folded into the
    linear layers of the returned :class:`PosePrior`, which runs in numpy. Deterministic for a
    seed on one thread (``torch.set_num_threads(1)``).

    Parameters
    ----------
    train, validation : sequences of ndarray, shape (F, 12, 3)
    width, blocks, dropout : network size and dropout probability during training
    epochs, samples_per_epoch, batch_size, weight_decay, window, seed, aug, future
        As in :func:`train_prior`.
    lr : (float, float)
        Adam's step size at the first and at the last epoch (as ``lr``, ``lr_final`` of
        :func:`train_prior`).

    Returns
    -------
    PosePrior
    """
    import torch

    torch.set_num_threads(1)
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    start = _start(train, validation, samples_per_epoch, rng, seed, aug, window, future)
    net = _ResidualNet.build(FRAME_DIM * window, width, blocks, dropout)
    lr_first, lr_final = lr
    opt = torch.optim.AdamW(net.modules.parameters(), lr=lr_first, weight_decay=weight_decay)
    decay = (lr_final / lr_first) ** (1.0 / max(1, epochs - 1))
    gen = torch.Generator().manual_seed(seed)
    t0 = time.perf_counter()
    batch = start.first
    loss_val = float("nan")
    for ep in range(epochs):
        if ep > 0:
            batch = make_batch(train, samples_per_epoch, rng, aug, window, future)
        for g in opt.param_groups:
            g["lr"] = lr_first * decay ** ep
        loss_val = _residual_epoch(net, opt, gen, batch, start, batch_size)
        if log is not None:
            mm, _ = _evaluate(_fold_residual(net.stem, net.body, net.head, start.out_mean, start.out_scale,
                                             window), start.val)
            log(f"epoch {ep + 1}/{epochs}: loss {loss_val:.4f}, validation P-MPJPE {mm:.1f} mm, "
                f"{time.perf_counter() - t0:.0f} s")
    prior = _fold_residual(net.stem, net.body, net.head, start.out_mean, start.out_scale, window)
    mm, err = _evaluate(prior, start.val)
    meta = {"validation_p_mpjpe_mm": round(mm, 2), "model": "residual", "width": width, "blocks": blocks,
            "dropout": dropout, "epochs": epochs, "samples_per_epoch": samples_per_epoch, "seed": seed,
            "lr": lr_first, "lr_final": lr_final, "weight_decay": weight_decay, "batch_size": batch_size,
            "augmentation": aug.__dict__, "future_frames": future, "final_loss": round(loss_val, 5),
            "train_seconds": round(time.perf_counter() - t0, 1), "torch": torch.__version__}
    return replace(prior, abs_error=np.maximum(err, 1e-6), metadata=meta)


def fold_linear_bn(weight: NDArray[np.float64], bias: NDArray[np.float64], gamma: NDArray[np.float64],
                   beta: NDArray[np.float64], mean: NDArray[np.float64], var: NDArray[np.float64],
                   eps: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``Linear -> BatchNorm`` in evaluation mode as one linear layer (``x @ W' + b'``).

    Parameters
    ----------
    weight : ndarray, shape (out, in)
        torch's ``Linear.weight``; ``bias`` (out,).
    gamma, beta, mean, var : ndarray, shape (out,)
        The batch norm's weight, bias, running mean and running variance; ``eps`` its epsilon.

    Returns
    -------
    W' : ndarray, shape (in, out)
        ``W.T s`` with ``s = gamma / sqrt(var + eps)``.
    b' : ndarray, shape (out,)
        ``(b - mean) s + beta``.
    """
    s = gamma / np.sqrt(var + eps)
    return weight.T * s, (bias - mean) * s + beta


def _fold_residual(stem: Any, body: Any, head: Any, out_mean: NDArray[np.float64],
                   out_scale: NDArray[np.float64], window: int) -> PosePrior:
    """The trained torch modules (eval mode: dropout off, batch norm by its running statistics)
    as a numpy :class:`PosePrior`, each ``Linear -> BatchNorm`` folded (:func:`fold_linear_bn`)."""

    def arr(t: Any) -> NDArray[np.float64]:
        return np.asarray(t.detach().double().numpy())

    def fold(lin: Any, bn: Any) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        return fold_linear_bn(arr(lin.weight), arr(lin.bias), arr(bn.weight), arr(bn.bias),
                              arr(bn.running_mean), arr(bn.running_var), float(bn.eps))

    layers = [fold(stem[0], stem[1])]
    for blk in body:
        layers += [fold(blk[0], blk[1]), fold(blk[4], blk[5])]
    layers.append((arr(head.weight).T, arr(head.bias)))
    return PosePrior(tuple(np.ascontiguousarray(w) for w, _ in layers),
                     tuple(np.ascontiguousarray(b) for _, b in layers),
                     out_mean, out_scale, np.ones((N_JOINTS, 3)), window, {}, len(body))
