"""A learned 2D -> 3D pose prior: a small MLP from normalised 2D keypoints to all 12 joints in 3D.

The network is data (VideoPose3D keeps the model definition apart from its weights): a ReLU
multilayer perceptron, plain or with residual blocks (Martinez et al. 2017: an input layer,
``blocks`` blocks ``h + relu(relu(h W_a + b_a) W_b + b_b)``, a linear output layer; the
training's batch normalisation folded into the linear layers), whose weights, normalisation
constants and per-joint uncertainty are one ``.npz`` file, loaded with ``allow_pickle=False`` and
validated before use. Inference is plain numpy (a few matrix products per pose, batched
offline). The packaged priors (``make prior``, ``make prior-temporal``: tools/train_prior.py) are
residual priors of 512 units and 2 blocks, 4.1 and 4.3 MB.

Input (:func:`normalise_2d`), per frame: the visible joints' 2D centred on their centroid ``c``
and divided by their RMS distance ``r`` from it, missing joints set to 0, and the 12 visibility
flags: 36 numbers. A causal temporal variant (``window > 1``) stacks the track's last ``window``
frames (oldest first), each normalised with the *current* frame's ``c`` and ``r`` so the motion
is kept; missing frames are all-missing.

Output, shape (12, 3), in the same units: ``x, y`` in the input's normalised image frame (a
visible joint's ``x, y`` are close to its input; a missing joint's are predicted), ``z`` the
depth along the camera's optical axis (forward) relative to the joints' mean depth. The frame is
the camera's optical frame (x right, y down, z forward), a proper rotation of the world.

``abs_error`` (12, 3) is the mean absolute error of each output on held-out training-split
frames: the scale ``b`` of a Laplace model of the prior's error, which the hybrid lifter uses to
weight its L1 prior term (``1 / b``).
"""

from __future__ import annotations

import functools
import json
import math
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

import numpy as np
from numpy.typing import NDArray

from ..errors import InvalidInputError, PriorFileError
from ..numeric.jit import HAVE_NUMBA, njit
from ..numeric.threads import thread_pool
from .prior_kernels import affine_rows as _affine_rows
from .skeleton import COUNTERPART, N_JOINTS

__all__ = ["DEFAULT_CUT_PRIOR_PATH", "DEFAULT_OFFLINE_CUT_PRIOR_PATH", "DEFAULT_OFFLINE_PRIOR_PATH",
           "DEFAULT_PRIOR_PATH", "DEFAULT_TEMPORAL_PRIOR_PATH", "PosePrior", "flip_rows", "normalise_2d",
           "prior_features"]

#: The prior shipped with the package (``make prior``: tools/train_prior.py).
DEFAULT_PRIOR_PATH: Final[Path] = Path(__file__).resolve().parents[2] / "data" / "prior_mlp.npz"
#: The causal temporal variant (a window of the track's last 4 frames at 30 Hz, no look-ahead):
#: ``make prior-temporal``.
DEFAULT_TEMPORAL_PRIOR_PATH: Final[Path] = DEFAULT_PRIOR_PATH.with_name("prior_mlp_w4.npz")
#: The temporal variant of a lift that knows each track's next frames (``pose-lifter lift``): a
#: window of 7 frames at 30 Hz centred on the lifted one, 3 before and 3 after:
#: ``make prior-offline``.
DEFAULT_OFFLINE_PRIOR_PATH: Final[Path] = DEFAULT_PRIOR_PATH.with_name("prior_mlp_w7c.npz")
#: The causal temporal variant trained with a tenth of its samples cut by the image's top and
#: bottom borders (a person close to the camera), for the tracked frames whose 2D lacks a
#: shoulder: ``make prior-temporal-cut``.
DEFAULT_CUT_PRIOR_PATH: Final[Path] = DEFAULT_TEMPORAL_PRIOR_PATH.with_name("prior_mlp_w4_crop.npz")
#: The same of the offline variant: ``make prior-offline-cut``.
DEFAULT_OFFLINE_CUT_PRIOR_PATH: Final[Path] = DEFAULT_PRIOR_PATH.with_name("prior_mlp_w7c_crop.npz")
_FORMAT_VERSION: Final[int] = 1
#: Format of a prior with residual blocks (adds the member ``blocks``).
_FORMAT_VERSION_RESIDUAL: Final[int] = 2
#: Loader caps: uncompressed bytes of the whole file, layers, units per layer, window.
MAX_FILE_BYTES: Final[int] = 64 * 1024 * 1024
MAX_LAYERS: Final[int] = 8
MAX_WIDTH: Final[int] = 4096
MAX_WINDOW: Final[int] = 64
FRAME_DIM: Final[int] = 3 * N_JOINTS  # 24 coordinates + 12 visibility flags
OUT_DIM: Final[int] = 3 * N_JOINTS


def normalise_2d(points: NDArray[np.float64], visible: NDArray[np.bool_]
                 ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Centre and scale 2D keypoints on their visible joints.

    Parameters
    ----------
    points : ndarray, shape (..., 12, 2)
    visible : ndarray of bool, shape (..., 12)
        At least 2 visible joints per frame, not all at one point.

    Returns
    -------
    u : ndarray, shape (..., 12, 2)
        ``(x - c) / r`` for visible joints, 0 for missing ones.
    centre : ndarray, shape (..., 2)
    radius : ndarray, shape (...)
        RMS distance of the visible joints from ``centre``.
    """
    x = np.asarray(points, dtype=np.float64)
    vis = np.asarray(visible, dtype=bool)
    vw = vis.astype(np.float64)
    n = vw.sum(axis=-1)
    if np.any(n < 2):
        raise InvalidInputError("the prior needs at least 2 visible joints")
    xz = np.where(vis[..., None], x, 0.0)
    centre = np.einsum("...j,...ja->...a", vw, xz) / n[..., None]
    d = np.where(vis[..., None], xz - centre[..., None, :], 0.0)
    radius = np.sqrt(np.einsum("...ja,...ja->...", d, d) / n)
    if not np.all(np.isfinite(radius)) or np.any(radius <= 1e-12):
        raise InvalidInputError("the visible keypoints are (almost) all at one point")
    return d / radius[..., None, None], centre, radius


def prior_features(points: NDArray[np.float64], visible: NDArray[np.bool_], window: int = 1,
                   anchor: int | None = None
                   ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Network input of frames or windows.

    Parameters
    ----------
    points : ndarray, shape (..., window, 12, 2) (or (..., 12, 2) when ``window == 1``)
    visible : ndarray of bool, shape (..., window, 12) (or (..., 12))
        The window's frame ``anchor`` needs >= 2 visible joints. Joints with non-finite
        coordinates count as missing.
    window : int
    anchor : int, optional
        The frame every frame of the window is normalised on (the lifted one; default the last).

    Returns
    -------
    features : ndarray, shape (..., 36 * window)
    centre : ndarray, shape (..., 2)
    radius : ndarray, shape (...)
        The anchor frame's normalisation (:func:`normalise_2d`).
    """
    a = window - 1 if anchor is None else int(anchor)
    if not 0 <= a < window:
        raise InvalidInputError(f"anchor must be in [0, {window}), got {anchor!r}")
    x = np.asarray(points, dtype=np.float64)
    vis = np.asarray(visible, dtype=bool)
    if window == 1 and x.shape == (N_JOINTS, 2) and vis.shape == (N_JOINTS,):
        return _compiled_features(x[None], vis[None], 0)
    if window > 1 and x.shape == (window, N_JOINTS, 2) and vis.shape == (window, N_JOINTS):
        return _compiled_features(x, vis, a)
    vis = vis & np.all(np.isfinite(x), axis=-1)
    if window == 1 and (x.ndim < 3 or x.shape[-3] != 1):
        x, vis = x[..., None, :, :], vis[..., None, :]
    if x.shape[-3:] != (window, N_JOINTS, 2) or vis.shape != x.shape[:-1]:
        raise InvalidInputError(f"points must be (..., {window}, {N_JOINTS}, 2) with visibility "
                                f"(..., {window}, {N_JOINTS}), got {x.shape} and {vis.shape}")
    _, centre, radius = normalise_2d(x[..., a, :, :], vis[..., a, :])
    xz = np.where(vis[..., None], x, 0.0)
    u = np.where(vis[..., None], (xz - centre[..., None, None, :]) / radius[..., None, None, None], 0.0)
    feats = np.concatenate([u.reshape(*u.shape[:-2], 2 * N_JOINTS), vis.astype(np.float64)], axis=-1)
    return feats.reshape(*feats.shape[:-2], FRAME_DIM * window), centre, radius


def _frame_features(x: NDArray[np.float64], vis: NDArray[np.bool_]
                    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """:func:`prior_features` of one frame (12, 2) with its visibility (12,) (finite where
    visible): the same values in a few numpy calls (the per-frame path of the node)."""
    n = int(np.count_nonzero(vis))
    if n < 2:
        raise InvalidInputError("the prior needs at least 2 visible joints")
    xv = x[vis]
    centre = xv.mean(axis=0)
    d = xv - centre
    radius = np.sqrt(np.sum(d * d) / n)
    if not np.isfinite(radius) or radius <= 1e-12:
        raise InvalidInputError("the visible keypoints are (almost) all at one point")
    feats = np.zeros(FRAME_DIM)
    u = feats[: 2 * N_JOINTS].reshape(N_JOINTS, 2)
    u[vis] = d / radius
    feats[2 * N_JOINTS:] = vis
    return feats, centre, np.asarray(radius)


@njit
def _features_kernel(x: NDArray[np.float64], visible: NDArray[np.bool_], anchor: int
                     ) -> tuple[NDArray[np.float64], NDArray[np.float64], float, int]:
    """:func:`_window_features` of a window (W, 12, 2) (C-contiguous; W = 1: one frame) with its
    visibility (W, 12), joints with non-finite coordinates missing, normalised on its frame
    ``anchor`` (the centre the visible joints' mean, the radius the root mean square of their
    coordinates about it): the values of :func:`_window_features` to round-off. Returns
    ``(features (36 W,), centre (2,), radius, visible joints of the anchor frame)``; the features
    are zero where :func:`_window_features` raises (fewer than 2 visible joints, a radius not
    finite or <= 1e-12)."""
    w = x.shape[0]
    nj = x.shape[1]
    vis = np.empty((w, nj), dtype=np.bool_)
    for f in range(w):
        for j in range(nj):
            vis[f, j] = visible[f, j] and math.isfinite(x[f, j, 0]) and math.isfinite(x[f, j, 1])
    n = 0
    c0 = 0.0
    c1 = 0.0
    for j in range(nj):
        if vis[anchor, j]:
            n += 1
            c0 += x[anchor, j, 0]
            c1 += x[anchor, j, 1]
    feats = np.zeros(w * 3 * nj)
    centre = np.empty(2)
    if n < 2:
        return feats, centre, 0.0, n
    c0 /= n
    c1 /= n
    centre[0], centre[1] = c0, c1
    sq = 0.0
    for j in range(nj):
        if vis[anchor, j]:
            d0 = x[anchor, j, 0] - c0
            d1 = x[anchor, j, 1] - c1
            sq += d0 * d0 + d1 * d1
    radius = math.sqrt(sq / n)
    if not (math.isfinite(radius) and radius > 1e-12):
        return feats, centre, radius, n
    for f in range(w):
        base = f * 3 * nj
        for j in range(nj):
            if vis[f, j]:
                feats[base + 2 * j] = (x[f, j, 0] - c0) / radius
                feats[base + 2 * j + 1] = (x[f, j, 1] - c1) / radius
                feats[base + 2 * nj + j] = 1.0
    return feats, centre, radius, n


def _compiled_features(x: NDArray[np.float64], visible: NDArray[np.bool_], anchor: int
                       ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """:func:`prior_features` of one window (W, 12, 2) and its visibility (W, 12) (W = 1: a frame,
    its features (36,)) normalised on its frame ``anchor``, by :func:`_features_kernel`: the
    values of :func:`_window_features` (:func:`_frame_features`), the per-frame path of the
    lifter."""
    feats, centre, radius, n = _features_kernel(np.ascontiguousarray(x, dtype=np.float64),
                                                np.ascontiguousarray(visible, dtype=np.bool_), anchor)
    if n < 2:
        raise InvalidInputError("the prior needs at least 2 visible joints")
    if not (math.isfinite(radius) and radius > 1e-12):
        raise InvalidInputError("the visible keypoints are (almost) all at one point")
    return feats, centre, np.asarray(radius)


def _window_features(x: NDArray[np.float64], vis: NDArray[np.bool_], anchor: int = -1
                     ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """:func:`prior_features` of one window (W, 12, 2) with its visibility (W, 12) (finite where
    visible), normalised on its frame ``anchor`` (default the last) as :func:`_frame_features`
    does: the same values in a few numpy calls (the reference of :func:`_features_kernel`)."""
    own, centre, radius = _frame_features(x[anchor], vis[anchor])
    feats = np.zeros((len(x), FRAME_DIM))
    u = feats[:, : 2 * N_JOINTS].reshape(len(x), N_JOINTS, 2)
    u[vis] = (x[vis] - centre) / radius
    feats[:, 2 * N_JOINTS:] = vis
    feats[anchor] = own
    return feats.reshape(FRAME_DIM * len(x)), centre, radius


#: Joint order of the mirror image: left and right swapped (``_MIRROR[j]`` is ``j``'s counterpart).
_MIRROR: Final[NDArray[np.intp]] = np.array(COUNTERPART, dtype=np.intp)
_FLIP_X: Final[NDArray[np.float64]] = np.array([-1.0, 1.0, 1.0])


def mirror_features(features: NDArray[np.float64]) -> NDArray[np.float64]:
    """Network input (..., 36 * window) of the mirrored image: each frame's normalised ``x``
    negated, left and right joints (coordinates and visibility flags) swapped."""
    f = np.asarray(features, dtype=np.float64)
    frames = f.reshape(*f.shape[:-1], -1, FRAME_DIM)
    u = frames[..., : 2 * N_JOINTS].reshape(*frames.shape[:-1], N_JOINTS, 2)[..., _MIRROR, :]
    u = u * np.array([-1.0, 1.0])
    vis = frames[..., 2 * N_JOINTS:][..., _MIRROR]
    out = np.concatenate([u.reshape(*frames.shape[:-1], 2 * N_JOINTS), vis], axis=-1)
    return out.reshape(f.shape)


def flip_rows(features: NDArray[np.float64], flip: bool) -> NDArray[np.float64]:
    """The network's input rows for ``features`` (..., 36 * window): with ``flip`` (test-time flip
    averaging) stacked with their mirror image, (..., 2, 36 * window); else the features."""
    return np.stack([features, mirror_features(features)], axis=-2) if flip else features


def mirror_pose(pose: NDArray[np.float64]) -> NDArray[np.float64]:
    """A pose (..., 12, 3) in the camera frame mirrored left-right: ``x`` negated, left and right
    joints swapped (its own inverse)."""
    out: NDArray[np.float64] = np.asarray(pose, dtype=np.float64)[..., _MIRROR, :] * _FLIP_X
    return out



#: Rows up to which :meth:`PosePrior.forward` runs the compiled layer pass instead of BLAS.
SMALL_BATCH: Final[int] = 8

#: Rows a thread of :meth:`PosePrior.forward_rows` takes at least: a part reads every layer's
#: weights (4 MB), which a few rows do not repay.
_ROWS_PER_THREAD: Final[int] = 8


@dataclass(frozen=True)
class PosePrior:
    """A trained 2D -> 3D MLP (see the module docstring for its input and output).

    Attributes
    ----------
    weights : tuple of ndarray
        ``W_i``, shape ``(n_i, n_{i+1})``; ``n_0 = 36 * window``, last ``n = 36``.
    biases : tuple of ndarray
        ``b_i``, shape ``(n_{i+1},)``.
    out_mean, out_scale : ndarray, shape (36,)
        The network predicts ``(y - out_mean) / out_scale``.
    abs_error : ndarray, shape (12, 3)
        Mean absolute error per output on held-out frames (> 0).
    window : int
        Frames per input (1 = single frame; > 1 a temporal variant).
    blocks : int
        Residual blocks (0: a plain MLP). With ``blocks = k`` there are ``2 k + 2`` layers: the
        input layer, two square layers per block, the output layer.
    metadata : dict
        Training data, augmentation, command, seed, validation figures; ``future_frames`` (an
        int, default 0) is :attr:`future_frames`.
    """

    weights: tuple[NDArray[np.float64], ...]
    biases: tuple[NDArray[np.float64], ...]
    out_mean: NDArray[np.float64]
    out_scale: NDArray[np.float64]
    abs_error: NDArray[np.float64]
    window: int = 1
    metadata: dict[str, Any] = field(default_factory=dict)
    blocks: int = 0
    #: float32 copies of the weights and biases, for inference (see :meth:`forward`)
    _layers32: tuple[tuple[NDArray[np.float32], NDArray[np.float32]], ...] = field(
        init=False, repr=False, compare=False, default=())
    #: the hybrid lifter's prior-row weights (12, 2) per (xy, z) weight pair
    #: (:meth:`pose_lifter.core.lift.hybrid.PriorFit._prior_rows`; computed once, read only)
    row_weights: dict[tuple[float, float], NDArray[np.float64]] = field(
        init=False, repr=False, compare=False, default_factory=dict)
    #: the metadata's ``future_frames``, checked (:attr:`future_frames`)
    _future: int = field(init=False, repr=False, compare=False, default=0)

    def __post_init__(self) -> None:
        if not isinstance(self.window, int) or not 1 <= self.window <= MAX_WINDOW:
            raise PriorFileError(f"window must be an integer in [1, {MAX_WINDOW}], got {self.window!r}")
        if len(self.weights) != len(self.biases) or not 1 <= len(self.weights) <= MAX_LAYERS:
            raise PriorFileError(f"1..{MAX_LAYERS} layers with one bias each expected, got "
                                 f"{len(self.weights)} weights and {len(self.biases)} biases")
        if not isinstance(self.blocks, int) or self.blocks < 0 or (
                self.blocks > 0 and len(self.weights) != 2 * self.blocks + 2):
            raise PriorFileError(f"{self.blocks!r} residual blocks need {2 * self.blocks + 2} layers, "
                                 f"got {len(self.weights)}")
        n_in = FRAME_DIM * self.window
        for i, (w, b) in enumerate(zip(self.weights, self.biases, strict=True)):
            if w.ndim != 2 or w.shape[0] != n_in or b.shape != (w.shape[1],):
                raise PriorFileError(f"layer {i}: weights {w.shape} / bias {b.shape} do not chain "
                                     f"from {n_in} inputs")
            if w.shape[1] > MAX_WIDTH:
                raise PriorFileError(f"layer {i} has {w.shape[1]} units (at most {MAX_WIDTH})")
            if not (np.all(np.isfinite(w)) and np.all(np.isfinite(b))):
                raise PriorFileError(f"layer {i} has non-finite weights")
            if self.blocks > 0 and 0 < i <= 2 * self.blocks and w.shape[0] != w.shape[1]:
                raise PriorFileError(f"layer {i} of a residual block must be square, got {w.shape}")
            n_in = w.shape[1]
        if n_in != OUT_DIM:
            raise PriorFileError(f"the last layer must have {OUT_DIM} outputs, got {n_in}")
        checks = (("out_mean", self.out_mean, (OUT_DIM,)), ("out_scale", self.out_scale, (OUT_DIM,)),
                  ("abs_error", self.abs_error, (N_JOINTS, 3)))
        for name, arr, shape in checks:
            if arr.shape != shape or not np.all(np.isfinite(arr)):
                raise PriorFileError(f"{name} must be finite with shape {shape}, got {arr.shape}")
        if np.any(self.out_scale <= 0) or np.any(self.abs_error <= 0):
            raise PriorFileError("out_scale and abs_error must be positive")
        future = self.metadata.get("future_frames", 0)
        if not isinstance(future, int) or isinstance(future, bool) or not 0 <= future < self.window:
            raise PriorFileError(f"metadata future_frames must be an integer in [0, {self.window}) for a "
                                 f"window of {self.window}, got {future!r}")
        object.__setattr__(self, "_future", future)
        object.__setattr__(self, "_layers32", tuple(
            (np.ascontiguousarray(w, dtype=np.float32), np.ascontiguousarray(b, dtype=np.float32))
            for w, b in zip(self.weights, self.biases, strict=True)))

    @property
    def future_frames(self) -> int:
        """Frames of the window after the one the prior lifts: 0 for a causal prior (its window
        ends on the lifted frame), ``F > 0`` for an offline one whose window holds ``window - 1 - F``
        frames before the lifted one and ``F`` after it (``tools/train_prior.py --future``)."""
        return self._future

    # ------------------------------------------------------------------ files
    @classmethod
    def load(cls, path: str | Path | None = None) -> PosePrior:
        """Load and validate a prior file (None: the packaged one).

        Raises
        ------
        PriorFileError
            Missing, unreadable, too large (uncompressed size read from the zip directory before
            any array is loaded), missing members, wrong dtypes or shapes, non-finite values.
        """
        p = Path(path) if path is not None else DEFAULT_PRIOR_PATH
        try:
            with zipfile.ZipFile(p) as zf:
                total = sum(i.file_size for i in zf.infolist())
            if total > MAX_FILE_BYTES:
                raise PriorFileError(f"{p}: {total} bytes uncompressed (at most {MAX_FILE_BYTES})")
            with np.load(p, allow_pickle=False) as z:
                names = set(z.files)
                need = {"format_version", "n_layers", "window", "out_mean", "out_scale", "abs_error",
                        "metadata"}
                if not need <= names:
                    raise PriorFileError(f"{p}: missing members {sorted(need - names)}")
                version = int(z["format_version"])
                if version not in (_FORMAT_VERSION, _FORMAT_VERSION_RESIDUAL):
                    raise PriorFileError(f"{p}: format version {version}, expected {_FORMAT_VERSION} "
                                         f"or {_FORMAT_VERSION_RESIDUAL}")
                blocks = 0
                if version == _FORMAT_VERSION_RESIDUAL:
                    if "blocks" not in names:
                        raise PriorFileError(f"{p}: missing member 'blocks'")
                    blocks_raw = z["blocks"]
                    if blocks_raw.dtype.kind not in "iu" or blocks_raw.ndim != 0:
                        raise PriorFileError(f"{p}: blocks must be an integer")
                    blocks = int(blocks_raw)
                    if not 1 <= blocks <= (MAX_LAYERS - 2) // 2:
                        raise PriorFileError(
                            f"{p}: {blocks} residual blocks (1..{(MAX_LAYERS - 2) // 2} allowed)")
                n = int(z["n_layers"])
                if not 1 <= n <= MAX_LAYERS:
                    raise PriorFileError(f"{p}: {n} layers (1..{MAX_LAYERS} allowed)")
                arrays: dict[str, NDArray[np.float64]] = {}
                for key in [*(f"w{i}" for i in range(n)), *(f"b{i}" for i in range(n)),
                            "out_mean", "out_scale", "abs_error"]:
                    if key not in names:
                        raise PriorFileError(f"{p}: missing member {key!r}")
                    a = z[key]
                    if a.dtype.kind != "f":
                        raise PriorFileError(f"{p}: {key} has dtype {a.dtype}, expected floats")
                    arrays[key] = np.ascontiguousarray(a, dtype=np.float64)
                meta_raw = z["metadata"]
                if meta_raw.dtype.kind != "U" or meta_raw.ndim != 0:
                    raise PriorFileError(f"{p}: metadata must be a JSON string")
                meta = json.loads(str(meta_raw))
                if not isinstance(meta, dict):
                    raise PriorFileError(f"{p}: metadata must be a JSON object")
                window = int(z["window"])
        except PriorFileError:
            raise
        except (OSError, KeyError, ValueError, TypeError, zipfile.BadZipFile, EOFError) as exc:
            raise PriorFileError(f"cannot read prior file {p}: {exc}") from exc
        try:
            return cls(tuple(arrays[f"w{i}"] for i in range(n)), tuple(arrays[f"b{i}"] for i in range(n)),
                       arrays["out_mean"], arrays["out_scale"], arrays["abs_error"], window, meta, blocks)
        except PriorFileError as exc:
            raise PriorFileError(f"{p}: {exc}") from exc

    def save(self, path: str | Path) -> None:
        """Write the prior as an ``.npz`` (no pickled objects; weights stored as float32, which
        moves the outputs by ~1e-6 of their scale, inference runs in float64)."""
        arrays: dict[str, Any] = {f"w{i}": w.astype(np.float32) for i, w in enumerate(self.weights)}
        arrays.update({f"b{i}": b.astype(np.float32) for i, b in enumerate(self.biases)})
        if self.blocks > 0:
            arrays["blocks"] = np.int64(self.blocks)
        version = _FORMAT_VERSION_RESIDUAL if self.blocks > 0 else _FORMAT_VERSION
        np.savez_compressed(
            path, format_version=np.int64(version), n_layers=np.int64(len(self.weights)),
            window=np.int64(self.window), out_mean=self.out_mean, out_scale=self.out_scale,
            abs_error=self.abs_error, metadata=np.array(json.dumps(self.metadata, sort_keys=True)), **arrays)

    # ------------------------------------------------------------------ inference
    @functools.cached_property
    def relative_weights(self) -> NDArray[np.float64]:
        """(12, 2): per joint, the inverse of the error relative to its mean, for the hybrid
        objective's image-position rows (x and y averaged) and depth row."""
        e = self.abs_error
        exy = e[:, :2].mean(axis=1)
        return np.column_stack([exy.mean() / exy, e[:, 2].mean() / e[:, 2]])

    def features(self, points: NDArray[np.float64], visible: NDArray[np.bool_]
                 ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """:func:`prior_features` with this prior's window, normalised on the frame it lifts."""
        return prior_features(points, visible, self.window, self.window - 1 - self.future_frames)

    def forward(self, features: NDArray[np.float64]) -> NDArray[np.float64]:
        """The network: ``relu`` hidden layers (the residual blocks' outputs added to their
        inputs), linear output, de-standardised. Shape (..., 36 * window) -> (..., 12, 3)
        normalised output.

        The layers run in float32 (the file's precision): a single pose reads the weights
        (4.3 MB for the packaged residual prior of 512 units) once, and float32 halves that memory
        traffic (measured on a 2 x 768 MLP: 287 -> 130 us a pose); outputs move by ~1e-6 of their
        scale against float64. Up to :data:`SMALL_BATCH` rows (a frame, or a frame and its
        mirror image) go through one compiled pass over each layer's weights
        (:func:`_affine_rows`): BLAS packs the weights for a matrix product of 2 rows and took
        575 us for the residual prior's pose and mirror, the compiled pass 204 us (141 against
        211 us for one row)."""
        h: NDArray[Any] = np.asarray(features, dtype=np.float32)
        layers = self._layers32
        if HAVE_NUMBA and 1 <= h.ndim <= 2 and h.size <= SMALL_BATCH * h.shape[-1]:
            return self._forward_small(h)
        if self.blocks == 0:
            last = len(layers) - 1
            for i, (w, b) in enumerate(layers):
                h = h @ w + b
                if i < last:
                    np.maximum(h, 0.0, out=h)
        else:
            h = h @ layers[0][0] + layers[0][1]
            np.maximum(h, 0.0, out=h)
            for k in range(self.blocks):
                (wa, ba), (wb, bb) = layers[1 + 2 * k], layers[2 + 2 * k]
                a = h @ wa + ba
                np.maximum(a, 0.0, out=a)
                a = a @ wb + bb
                np.maximum(a, 0.0, out=a)
                h = h + a
            h = h @ layers[-1][0] + layers[-1][1]
        y = h.astype(np.float64) * self.out_scale + self.out_mean
        return y.reshape(*y.shape[:-1], N_JOINTS, 3)

    def forward_rows(self, x: NDArray[np.float32], threads: int = 1) -> NDArray[np.float64]:
        """:meth:`_forward_small` of the rows ``x`` (n, 36 * window), split into ``threads``
        contiguous parts run in parallel (:func:`pose_lifter.core.numeric.threads.thread_pool`;
        the compiled pass releases the GIL): (n, 12, 3), each row's the same bit for bit whatever
        the split."""
        parts = min(max(threads, 1), x.shape[0] // _ROWS_PER_THREAD)
        if parts <= 1:
            return self._forward_small(x)
        edges = [round(i * x.shape[0] / parts) for i in range(parts + 1)]
        done = thread_pool(parts).map(lambda i: self._forward_small(x[edges[i]:edges[i + 1]]), range(parts))
        return np.concatenate(list(done))

    def _forward_small(self, x: NDArray[np.float32]) -> NDArray[np.float64]:
        """:meth:`forward` through the compiled layer pass (:meth:`forward` sends it 1 to
        SMALL_BATCH rows; :func:`pose_lifter.core.lift.batch.prior_calls` any number). Each
        row's arithmetic is independent of the others': a row's output is the same bit for bit
        in a pass of 2 rows or of 200."""
        h = np.ascontiguousarray(x.reshape(-1, x.shape[-1]))
        layers = self._layers32
        if self.blocks == 0:
            last = len(layers) - 1
            for i, (w, b) in enumerate(layers):
                h = _affine_rows(h, w, b, i < last)
        else:
            h = _affine_rows(h, layers[0][0], layers[0][1], True)
            for k in range(self.blocks):
                (wa, ba), (wb, bb) = layers[1 + 2 * k], layers[2 + 2 * k]
                h = h + _affine_rows(_affine_rows(h, wa, ba, True), wb, bb, True)
            h = _affine_rows(h, layers[-1][0], layers[-1][1], False)
        y = h.astype(np.float64) * self.out_scale + self.out_mean
        return y.reshape(*x.shape[:-1], N_JOINTS, 3)

    def input_rows(self, points: NDArray[np.float64], visible: NDArray[np.bool_], flip: bool = False
                   ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """The network's input rows for :meth:`predict`: the features (..., 36 * window), with
        ``flip`` stacked with their mirror image (..., 2, 36 * window); and the current frame's
        centre (..., 2) and radius (...) (:func:`prior_features`)."""
        feats, centre, radius = self.features(points, visible)
        return flip_rows(feats, flip), centre, radius

    def predict(self, points: NDArray[np.float64], visible: NDArray[np.bool_], flip: bool = False
                ) -> NDArray[np.float64]:
        """3D poses in input units: ``x, y`` in the image (``c + r u``), ``z`` relative depth
        (``r z``), shape (..., 12, 3) for input as in :meth:`features`.

        With ``flip`` the prediction is the mean of the network's answer for the input and its
        answer for the mirrored input (the image flipped left-right, left and right joints
        swapped), mirrored back (test-time flip averaging): a person and their mirror image are
        equally likely, so the two answers' errors are partly independent. Both go through the
        network as one batch of two (the cost of one pose: the weights are read once)."""
        rows, centre, radius = self.input_rows(points, visible, flip)
        return self.poses(self.forward(rows), centre, radius, flip)

    def poses(self, outputs: NDArray[np.float64], centre: NDArray[np.float64], radius: NDArray[np.float64],
              flip: bool) -> NDArray[np.float64]:
        """:meth:`predict`'s poses (..., 12, 3) from the network's ``outputs`` for the rows of
        :meth:`input_rows` (with ``flip``, (..., 2, 12, 3): averaged with the mirror image's)."""
        y = outputs
        if flip:
            y = 0.5 * (y[..., 0, :, :] + mirror_pose(y[..., 1, :, :]))
        out = y * radius[..., None, None]
        out[..., :2] += centre[..., None, :]
        return out

