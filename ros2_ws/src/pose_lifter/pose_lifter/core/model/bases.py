"""Pose bases: a 3D pose is ``mean + B @ alpha`` in the normalised model frame.

Learning (paper Sec. 4.2): sparse bases by L1-regularised dictionary learning
(Mairal et al.; the paper's choice), PCA, and class-wise PCA (Ramakrishna et al. 2012).
Poses are normalised with :func:`pose_lifter.core.model.skeleton.normalise_pose` first
(centred, body frame, right lower leg = 1).
"""

from __future__ import annotations

import json
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

import numpy as np
from numpy.typing import NDArray

from ..errors import BasisFileError, InvalidInputError
from .skeleton import N_JOINTS, limb_lengths

__all__ = [
    "DEFAULT_BASES_PATH",
    "HYBRID_BASES_PATH",
    "MAX_COMPONENTS",
    "MAX_METADATA_CHARS",
    "MAX_START_POSES",
    "PoseBases",
    "default_bases_path",
    "learn_classwise_pca_bases",
    "learn_pca_bases",
    "learn_sparse_bases",
    "npz_member_shapes",
    "sparse_codes",
]

#: The basis file shipped with the package for the paper's mode and experiments: the paper's
#: protocol, subject 01's playground trials (see tools/learn_default_bases.sh).
DEFAULT_BASES_PATH: Final[Path] = Path(__file__).resolve().parents[2] / "data" / "bases_sparse200.npz"
#: The basis file of the product's hybrid and learned modes: the same learning on the trials the
#: learned prior was fitted on (the training split minus the prior's validation trials), every
#: frame's limbs scaled by up to +-20 % first, so the bases represent people of other
#: proportions (tools/learn_default_bases.sh).
HYBRID_BASES_PATH: Final[Path] = DEFAULT_BASES_PATH.with_name("bases_hybrid_sparse200.npz")


def default_bases_path(mode: str) -> Path:
    """The packaged basis file of a lifter mode: ``"paper"`` -> :data:`DEFAULT_BASES_PATH`, the
    others (``"hybrid"``, ``"learned"``) -> :data:`HYBRID_BASES_PATH`."""
    return DEFAULT_BASES_PATH if mode == "paper" else HYBRID_BASES_PATH
_FORMAT_VERSION: Final[int] = 1
#: Caps of a basis file, checked in the ``.npy`` headers before any data is read (a 2 MB
#: ``.npz`` can otherwise expand to gigabytes): multi-start coefficient rows, bases ``k``, and
#: characters of the JSON metadata. The packaged file has 30 starts, k = 200, 800 characters.
MAX_START_POSES: Final[int] = 10_000
MAX_COMPONENTS: Final[int] = 5_000
MAX_METADATA_CHARS: Final[int] = 1_000_000
#: Column norm below which a basis vector is degenerate (the learned ones have norm 1).
_MIN_COMPONENT_NORM: Final[float] = 1e-9


@dataclass
class PoseBases:
    """A learned pose model.

    Attributes
    ----------
    mean : ndarray, shape (36,)
        Mean pose ``mu`` (joint-major, model frame, right lower leg = 1).
    components : ndarray, shape (36, k)
        The bases ``B`` as columns.
    method : str
        ``"sparse"``, ``"pca"`` or ``"classwise-pca"``.
    start_alphas : ndarray, shape (n_starts, k)
        Coefficients of k-means cluster centres of the training poses: the multi-start
        initialisations (paper Sec. 4.4.2). Row 0 is always the mean pose (zeros).
    limb_proportions : ndarray, shape (8,)
        Mean limb lengths of the training poses (right lower leg = 1).
    metadata : dict
        Free-form description: training data, learning parameters, command.
    """

    mean: NDArray[np.float64]
    components: NDArray[np.float64]
    method: str
    start_alphas: NDArray[np.float64]
    limb_proportions: NDArray[np.float64]
    metadata: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.mean = np.asarray(self.mean, dtype=np.float64).reshape(-1)
        self.components = np.asarray(self.components, dtype=np.float64)
        self.start_alphas = np.atleast_2d(np.asarray(self.start_alphas, dtype=np.float64))
        self.limb_proportions = np.asarray(self.limb_proportions, dtype=np.float64)
        d = 3 * N_JOINTS
        if self.mean.shape != (d,):
            raise BasisFileError(f"mean must have {d} entries, got {self.mean.shape}")
        if self.components.ndim != 2 or self.components.shape[0] != d:
            raise BasisFileError(f"components must be ({d}, k), got {self.components.shape}")
        if self.start_alphas.shape[1] != self.n_bases:
            raise BasisFileError("start_alphas must have one column per basis")
        if self.limb_proportions.shape != (8,):
            raise BasisFileError("limb_proportions must have 8 entries")
        for name, arr in (("mean", self.mean), ("components", self.components),
                          ("start_alphas", self.start_alphas)):
            if not np.all(np.isfinite(arr)):
                raise BasisFileError(f"{name} has non-finite values")
        if self.n_bases < 1:
            raise BasisFileError("components must have at least one basis (k >= 1), got k = 0")
        if self.start_alphas.shape[0] < 1:
            raise BasisFileError("start_alphas must have at least one start (row 0: the mean pose)")
        if not np.all(np.isfinite(self.limb_proportions)) or not np.all(self.limb_proportions > 0):
            raise BasisFileError("limb_proportions must be 8 finite positive lengths, got "
                                 f"{np.array2string(self.limb_proportions, precision=3)}")
        norms = np.linalg.norm(self.components, axis=0)
        if np.any(norms < _MIN_COMPONENT_NORM):
            bad = np.flatnonzero(norms < _MIN_COMPONENT_NORM)
            raise BasisFileError(f"{bad.size} of {self.n_bases} components are (almost) zero vectors "
                                 f"(first: column {int(bad[0])})")

    @property
    def n_bases(self) -> int:
        """Number of bases ``k``."""
        return int(self.components.shape[1])

    @property
    def mean_pose(self) -> NDArray[np.float64]:
        """The mean pose, shape (12, 3)."""
        return self.mean.reshape(N_JOINTS, 3)

    def pose(self, alpha: NDArray[np.float64]) -> NDArray[np.float64]:
        """``mean + B @ alpha`` as poses; alpha of shape (..., k) -> (..., 12, 3)."""
        a = np.asarray(alpha, dtype=np.float64)
        return np.asarray((self.mean + a @ self.components.T).reshape(*a.shape[:-1], N_JOINTS, 3))

    def with_starts(self, n_starts: int) -> NDArray[np.float64]:
        """The first ``n_starts`` multi-start coefficient vectors, shape (n, k)."""
        n = max(1, min(int(n_starts), self.start_alphas.shape[0]))
        return self.start_alphas[:n]

    def save(self, path: str | Path) -> None:
        """Write an ``.npz`` file (arrays + JSON metadata)."""
        meta = dict(self.metadata)
        meta["format_version"] = _FORMAT_VERSION
        meta["method"] = self.method
        meta["n_bases"] = self.n_bases
        np.savez_compressed(
            Path(path),
            mean=self.mean,
            components=self.components,
            start_alphas=self.start_alphas,
            limb_proportions=self.limb_proportions,
            metadata=np.array(json.dumps(meta, sort_keys=True)),
        )

    @classmethod
    def load(cls, path: str | Path | None = None) -> PoseBases:
        """Read and completely validate a basis file; ``None`` loads the packaged default.

        The file must be an ``.npz`` with exactly the members :meth:`save` writes. Member
        dtypes and shapes, and the caps :data:`MAX_START_POSES`, :data:`MAX_COMPONENTS` and
        :data:`MAX_METADATA_CHARS`, are checked in the ``.npy`` headers before any data is
        read; then the values (finite, positive limb proportions, non-zero components, at least
        one start). Nothing is unpickled.

        Raises
        ------
        BasisFileError
            For every problem, with the reason (never another exception type).
        """
        p = Path(path) if path is not None else DEFAULT_BASES_PATH
        if not p.is_file():
            raise BasisFileError(f"basis file not found: {p}")
        try:
            _check_npz_headers(p)
            with np.load(p, allow_pickle=False) as z:
                meta = json.loads(str(z["metadata"][()]))
                if not isinstance(meta, dict):
                    raise BasisFileError(f"metadata must be a JSON object, got {type(meta).__name__}")
                return cls(
                    mean=z["mean"],
                    components=z["components"],
                    method=str(meta.get("method", "unknown")),
                    start_alphas=z["start_alphas"],
                    limb_proportions=z["limb_proportions"],
                    metadata=meta,
                )
        except BasisFileError as exc:
            raise BasisFileError(f"bad basis file {p}: {exc}") from None
        except (KeyError, ValueError, OSError, EOFError, TypeError, zipfile.BadZipFile,
                RuntimeError, MemoryError) as exc:
            raise BasisFileError(f"cannot read basis file {p}: {exc}") from exc


#: Members of a basis file: name -> (dtype kinds allowed, number of dimensions).
_MEMBERS: Final[dict[str, tuple[str, int]]] = {
    "mean": ("f", 1),
    "components": ("f", 2),
    "start_alphas": ("f", 2),
    "limb_proportions": ("f", 1),
    "metadata": ("U", 0),
}


def npz_member_shapes(
    path: Path, members: dict[str, tuple[str, int]], max_string_chars: int = MAX_METADATA_CHARS
) -> dict[str, tuple[int, ...]]:
    """Shapes of an ``.npz``'s members, from its zip directory and ``.npy`` headers only.

    No array data is read, so a file whose headers announce gigabytes costs nothing; callers
    check the shapes against their caps before ``np.load``. Reusable for any ``.npz`` model file.

    Parameters
    ----------
    path : Path
    members : dict
        Exactly the members the file must hold: name (without ``.npy``) -> (allowed dtype kinds,
        e.g. ``"f"`` or ``"U"``, number of dimensions).
    max_string_chars : int
        Longest string allowed in a ``"U"`` member.

    Raises
    ------
    BasisFileError
        Not a zip, other members, an object / structured / unexpected dtype, wrong dimensions.
    """
    if not zipfile.is_zipfile(path):
        raise BasisFileError("not an .npz archive (PoseBases.save writes one)")
    with zipfile.ZipFile(path) as zf:
        names = {info.filename: info for info in zf.infolist()}
        expected = {f"{m}.npy" for m in members}
        if set(names) != expected:
            missing = sorted(expected - set(names))
            extra = sorted(set(names) - expected)
            raise BasisFileError(f"members must be {sorted(expected)}; missing {missing}, unexpected {extra}")
        shapes: dict[str, tuple[int, ...]] = {}
        for member, (kinds, ndim) in members.items():
            with zf.open(f"{member}.npy") as f:
                version = np.lib.format.read_magic(f)
                if version == (1, 0):
                    shape, _, dtype = np.lib.format.read_array_header_1_0(f)
                elif version == (2, 0):
                    shape, _, dtype = np.lib.format.read_array_header_2_0(f)
                else:
                    raise BasisFileError(f"{member}: unsupported .npy format version {version}")
            if dtype.kind not in kinds or dtype.hasobject or dtype.fields is not None:
                raise BasisFileError(f"{member} must be of dtype kind {kinds!r}, got {dtype}")
            if len(shape) != ndim:
                raise BasisFileError(f"{member} must have {ndim} dimensions, got shape {shape}")
            shapes[member] = tuple(int(n) for n in shape)
            if dtype.kind == "U" and dtype.itemsize // 4 > max_string_chars:
                raise BasisFileError(f"{member} of {dtype.itemsize // 4} characters, more than "
                                     f"{max_string_chars}")
    return shapes


def _check_npz_headers(path: Path) -> None:
    """Check a basis ``.npz`` against the caps from its headers only (no data read)."""
    shapes = npz_member_shapes(path, _MEMBERS)
    k = shapes["components"][1]
    if k > MAX_COMPONENTS:
        raise BasisFileError(f"{k} components, more than {MAX_COMPONENTS} (MAX_COMPONENTS)")
    n_starts = shapes["start_alphas"][0]
    if n_starts > MAX_START_POSES:
        raise BasisFileError(f"{n_starts} start poses, more than {MAX_START_POSES} (MAX_START_POSES)")
    if shapes["start_alphas"][1] != k:
        raise BasisFileError(f"start_alphas has {shapes['start_alphas'][1]} columns for {k} components")
    d = 3 * N_JOINTS
    if shapes["mean"] != (d,) or shapes["components"][0] != d or shapes["limb_proportions"] != (8,):
        raise BasisFileError(f"shapes must be mean ({d},), components ({d}, k), limb_proportions (8,); got "
                             f"{shapes['mean']}, {shapes['components']}, {shapes['limb_proportions']}")


def _as_training_matrix(poses: NDArray[np.float64]) -> NDArray[np.float64]:
    arr = np.asarray(poses, dtype=np.float64)
    if arr.ndim != 3 or arr.shape[1:] != (N_JOINTS, 3):
        raise InvalidInputError(f"training poses must be (N, {N_JOINTS}, 3), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise InvalidInputError("training poses contain non-finite values")
    return arr.reshape(arr.shape[0], -1)


def sparse_codes(
    poses: NDArray[np.float64], mean: NDArray[np.float64], components: NDArray[np.float64], theta: float
) -> NDArray[np.float64]:
    """L1-regularised coefficients of poses (paper Sec. 4.2 reconstruction test).

    Minimises ``0.5 * ||y - mu - B alpha||_2^2 + theta * ||alpha||_1`` per pose.

    Parameters
    ----------
    poses : ndarray, shape (N, 12, 3)
    mean : ndarray, shape (36,)
    components : ndarray, shape (36, k)
    theta : float

    Returns
    -------
    ndarray, shape (N, k)
    """
    from sklearn.linear_model import Lasso

    y = _as_training_matrix(poses) - mean
    d = y.shape[1]
    # sklearn's Lasso minimises 1/(2 n_samples) ||y - X w||^2 + a ||w||_1 with n_samples = d.
    model = Lasso(alpha=theta / d, fit_intercept=False, max_iter=5000, tol=1e-6)
    model.fit(components, y.T)
    return np.atleast_2d(np.asarray(model.coef_, dtype=np.float64))


def _kmeans_starts(
    x: NDArray[np.float64], mean: NDArray[np.float64], components: NDArray[np.float64],
    n_starts: int, seed: int, theta: float,
) -> NDArray[np.float64]:
    from sklearn.cluster import KMeans

    n_clusters = max(1, min(n_starts - 1, x.shape[0]))
    km = KMeans(n_clusters=n_clusters, n_init=4, random_state=seed).fit(x)
    centres = km.cluster_centers_.reshape(-1, N_JOINTS, 3)
    # order clusters by size, largest first, so a prefix of starts is the most useful one
    order = np.argsort(-np.bincount(km.labels_, minlength=n_clusters), kind="stable")
    codes = sparse_codes(centres[order], mean, components, theta)
    return np.vstack([np.zeros((1, components.shape[1])), codes])


def _finish(
    x: NDArray[np.float64], mean: NDArray[np.float64], comps: NDArray[np.float64], method: str,
    n_starts: int, seed: int, theta: float, metadata: dict[str, Any] | None,
) -> PoseBases:
    meta = dict(metadata or {})
    meta.update({"n_training_poses": int(x.shape[0]), "seed": seed, "n_starts": n_starts})
    props = limb_lengths(x.reshape(-1, N_JOINTS, 3)).mean(axis=0)
    return PoseBases(
        mean=mean,
        components=comps,
        method=method,
        start_alphas=_kmeans_starts(x, mean, comps, n_starts, seed, theta),
        limb_proportions=props / props[7],
        metadata=meta,
    )


def learn_sparse_bases(
    poses: NDArray[np.float64], n_bases: int = 200, sparsity: float = 0.1, n_starts: int = 30,
    seed: int = 0, n_iter: int = 2000, metadata: dict[str, Any] | None = None,
) -> PoseBases:
    """Sparse bases by L1-regularised dictionary learning (the paper's choice).

    Minimises ``sum_t 0.5 ||y_t - mu - B alpha_t||^2 + sparsity ||alpha_t||_1`` over unit-norm
    columns of ``B`` and the codes (scikit-learn ``MiniBatchDictionaryLearning``).

    Parameters
    ----------
    poses : ndarray, shape (N, 12, 3)
        Normalised training poses.
    n_bases : int
        ``k``; may exceed 36 (overcomplete, paper: 200).
    sparsity : float
        The L1 weight of learning (and of the cluster-centre codes).
    """
    from sklearn.decomposition import MiniBatchDictionaryLearning

    x = _as_training_matrix(poses)
    mean = x.mean(axis=0)
    dl = MiniBatchDictionaryLearning(
        n_components=n_bases, alpha=sparsity, max_iter=n_iter, batch_size=256,
        random_state=seed, transform_algorithm="lasso_cd", transform_alpha=sparsity,
        fit_algorithm="cd",
    )
    dl.fit(x - mean)
    comps = np.asarray(dl.components_, dtype=np.float64).T
    comps /= np.maximum(np.linalg.norm(comps, axis=0, keepdims=True), 1e-12)
    meta = {"sparsity": sparsity, **(metadata or {})}
    return _finish(x, mean, comps, "sparse", n_starts, seed, sparsity, meta)


def _principal_directions(x: NDArray[np.float64]) -> NDArray[np.float64]:
    """The rows of ``V^T`` of ``x = U S V^T``, shape (min(N, D), D), each signed so that its
    entry of largest magnitude is positive.

    An SVD fixes each direction only up to its sign, and which sign LAPACK returns depends on the
    BLAS kernel the machine runs. The convention makes the learned bases (and the start codes and
    the lifts' alphas expressed in them) the same on every machine.
    """
    _, _, vt = np.linalg.svd(x, full_matrices=False)
    lead = vt[np.arange(vt.shape[0]), np.abs(vt).argmax(axis=1)]
    return np.asarray(vt * np.where(lead < 0.0, -1.0, 1.0)[:, None])


def learn_pca_bases(
    poses: NDArray[np.float64], n_bases: int = 30, n_starts: int = 30, seed: int = 0,
    metadata: dict[str, Any] | None = None,
) -> PoseBases:
    """The first ``n_bases`` principal components (at most 36) as bases."""
    x = _as_training_matrix(poses)
    mean = x.mean(axis=0)
    vt = _principal_directions(x - mean)
    k = min(n_bases, vt.shape[0])
    return _finish(x, mean, vt[:k].T.copy(), "pca", n_starts, seed, 0.01, metadata)


def learn_classwise_pca_bases(
    poses: NDArray[np.float64], labels: NDArray[Any], n_per_class: int = 12, n_starts: int = 30,
    seed: int = 0, metadata: dict[str, Any] | None = None,
) -> PoseBases:
    """Class-wise PCA (Ramakrishna et al. 2012): PCA per action class, components stacked.

    Each class is centred on its own mean; the bases are expressed around the global mean.
    """
    x = _as_training_matrix(poses)
    lab = np.asarray(labels)
    if lab.shape != (x.shape[0],):
        raise InvalidInputError("labels must have one entry per pose")
    mean = x.mean(axis=0)
    cols: list[NDArray[np.float64]] = []
    for c in np.unique(lab):
        xc = x[lab == c]
        # class mean offset as one basis, then the class's principal directions
        offset = xc.mean(axis=0) - mean
        if np.linalg.norm(offset) > 1e-9:
            cols.append(offset / np.linalg.norm(offset))
        vt = _principal_directions(xc - xc.mean(axis=0))
        cols.extend(vt[: min(n_per_class, vt.shape[0])])
    comps = np.stack(cols, axis=1)
    meta = {"classes": [str(c) for c in np.unique(lab)], "n_per_class": n_per_class, **(metadata or {})}
    return _finish(x, mean, comps, "classwise-pca", n_starts, seed, 0.01, meta)
