"""Lift a collection of bags: several inputs, one output directory, resumable, local or on Dask.

``pose-lifter lift A.mcap B.mcap DIR/ 'runs/**/*.mcap' --out OUT/`` lifts every bag named, found
under a directory (recursively) or matched by a glob into ``OUT`` with the inputs' relative layout
(paths relative to the inputs' common directory). A bag is an ``.mcap`` file or a rosbag2
directory (a folder holding ``metadata.yaml``, as ``ros2 bag record`` writes it: one recording,
its split files read as one stream), lifted into ``<name>.mcap``; a directory without
``metadata.yaml`` is searched. Each bag is one task:

- **locally** (the default) on one process pool started once for the collection (fork: the
  lifter is built and its kernels loaded once in the parent, the workers inherit it); a bag is
  lifted serially inside its worker, so bags overlap one another (one reads or writes while the
  other solves). A collection of one bag is lifted by :func:`pose_lifter.offline.lift.lift_bag` with
  its tracks spread over the workers instead.
- **on a Dask cluster** (``--scheduler ADDRESS``, the ``cluster`` extra: ``dask.distributed``):
  one task per bag through a ``distributed.Client``; every worker builds the lifter from the
  same :class:`LiftSettings` once per process. Inputs and outputs must be paths that every
  worker reads and writes under the same names (a shared file system); the outputs are written
  by the workers, the manifest by this process.

A bag's output appears under its final name only when complete (:class:`pose_lifter.offline.bags.BagWriter`
writes into a hidden ``.bagwriter-*`` directory beside it and renames the finished file), so a
stopped run leaves only whole outputs. After each bag the manifest ``pose_lifter_manifest.json``
in ``OUT`` is rewritten (atomically: a temporary file renamed over it): per output, the input's
SHA-256, size and mtime (of a rosbag2 directory: over its files), the digest of the settings, the
package version and the counts. A bag whose entry matches (same settings digest, same version,
the output present, the input unchanged: same size and mtime, or else the same SHA-256) is
skipped; ``overwrite`` lifts it again. A bag that fails (a damaged file, no keypoints, ...) is
recorded as failed and the rest are lifted; its error and traceback go to
``pose_lifter_errors.txt`` in ``OUT``. One run per output directory at a time.
"""

from __future__ import annotations

import glob
import hashlib
import json
import os
import shutil
import signal
import sys
import threading
import time
import traceback
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

from pose_lifter.offline.bags import BagError, bag_path, bag_sha256, bag_stat, is_rosbag2_dir
from pose_lifter.offline.settings import LiftSettings, package_version

if TYPE_CHECKING:
    from pose_lifter.offline.lift import LiftSummary

__all__ = [
    "ERRORS_NAME",
    "MANIFEST_NAME",
    "BagJob",
    "BagOutcome",
    "CollectionSummary",
    "LiftSettings",
    "expand_inputs",
    "format_summary",
    "is_pattern",
    "lift_collection",
    "plan_jobs",
]

_GLOB_CHARS: Final[frozenset[str]] = frozenset("*?[")


def is_pattern(text: str) -> bool:
    """``text`` holds a glob wildcard (``*``, ``?``, ``[``)."""
    return any(c in text for c in _GLOB_CHARS)


# --------------------------------------------------------------------------- inputs -> jobs


def _recording_of(path: Path) -> Path | None:
    """The rosbag2 directory a glob's match names or lies in (the directory, its
    ``metadata.yaml``, a storage file beside it), if any."""
    p = bag_path(path)
    if is_rosbag2_dir(p):
        return p
    if p.is_file() and is_rosbag2_dir(p.parent):
        return p.parent
    return None


def _bags_under(directory: Path) -> list[Path]:
    """The bags under a directory that is not a recording itself: its ``.mcap`` files and its
    rosbag2 directories (each one bag, never searched inside), recursively."""
    found: list[Path] = []
    stack = [directory]
    seen: set[Path] = set()
    while stack:
        d = stack.pop()
        if d.resolve() in seen:  # a directory reached twice (symbolic links)
            continue
        seen.add(d.resolve())
        for x in sorted(d.iterdir()):
            if x.is_dir():
                if is_rosbag2_dir(x):
                    found.append(x)
                else:
                    stack.append(x)
            elif x.suffix == ".mcap" and x.is_file():
                found.append(x)
    return found


def expand_inputs(inputs: Sequence[str], exclude: str | Path | None = None) -> tuple[list[Path], Path]:
    """The bags named by ``inputs``, sorted and without duplicates, and the directory their
    outputs' relative paths start from (the common directory of the directories searched and of
    the bags' parents).

    A bag is an ``.mcap`` file or a rosbag2 directory (a folder holding ``metadata.yaml``: one
    recording, however many files it has; its ``metadata.yaml`` names it too). ``inputs`` are
    bags, directories searched recursively (a rosbag2 directory found is one bag, not searched
    inside) and glob patterns with ``**`` (a match inside a rosbag2 directory names the
    recording). Bags that directories and patterns find under ``exclude`` (the output directory:
    an earlier run's outputs) are left out.

    Raises
    ------
    BagError
        An input that does not exist, a directory or a pattern with no bag, or no bag at all.
    """
    skip = Path(exclude).resolve() if exclude is not None else None

    def kept(x: Path) -> bool:
        return skip is None or not x.resolve().is_relative_to(skip)

    bags: list[Path] = []
    roots: list[Path] = []
    for text in inputs:
        p = bag_path(text)
        if is_pattern(text) and not p.exists():
            found: list[Path] = []
            for x in (Path(m) for m in glob.glob(text, recursive=True)):
                rec = _recording_of(x)
                if rec is not None:
                    found.append(rec)
                elif x.is_file() and x.suffix == ".mcap":
                    found.append(x)
            found = [x for x in found if kept(x)]
            if not found:
                raise BagError(f"no .mcap file matches {text!r}, nor a rosbag2 directory")
            bags += found
            roots += [x.resolve().parent for x in found]
        elif is_rosbag2_dir(p):
            bags.append(p)
            roots.append(p.resolve().parent)
        elif p.is_dir():
            found = [x for x in _bags_under(p) if kept(x)]
            if not found:
                raise BagError(f"no .mcap file under {p}, nor a rosbag2 directory")
            bags += found
            roots.append(p.resolve())
        elif p.is_file():
            bags.append(p)
            roots.append(p.resolve().parent)
        else:
            raise BagError(f"bag not found: {p}")
    resolved = sorted({b.resolve() for b in bags})
    if not resolved:
        raise BagError("no bag input")
    root = Path(os.path.commonpath([str(r) for r in roots]))
    return resolved, root


@dataclass(frozen=True)
class BagJob:
    """One bag of a collection: absolute input (a file or a rosbag2 directory) and output paths,
    the manifest key, and the input's size and modification time
    (:func:`pose_lifter.offline.bags.bag_stat`)."""

    input: str
    output: str
    rel: str
    size: int
    mtime_ns: int


def plan_jobs(inputs: Sequence[str], out_dir: str | Path) -> list[BagJob]:
    """One :class:`BagJob` per input bag (see :func:`expand_inputs`), its output at the same
    relative path under ``out_dir`` (a rosbag2 directory ``rec/``: ``rec.mcap``); refuses an output
    that would replace its input or lie inside an input recording, and two inputs with one output."""
    out = Path(out_dir).resolve()
    files, root = expand_inputs(inputs, exclude=out)
    jobs = []
    seen: dict[Path, Path] = {}
    for f in files:
        rel = f.relative_to(root)
        if f.is_dir() and rel.suffix != ".mcap":
            rel = rel.with_name(f"{rel.name}.mcap")
        target = out / rel
        if target == f:
            raise BagError(f"the output of {f} would overwrite it: choose another --out")
        if f.is_dir() and target.is_relative_to(f):
            raise BagError(f"the output of {f} would be written inside the recording: choose another --out")
        if target in seen:
            raise BagError(f"{seen[target]} and {f} would both be lifted into {target}: rename one")
        seen[target] = f
        size, mtime_ns = bag_stat(f)
        jobs.append(BagJob(str(f), str(target), rel.as_posix(), size, mtime_ns))
    return jobs


# --------------------------------------------------------------------------- manifest

#: The names in the output directory of the manifest and of the failed bags' errors; the manifest's format.
MANIFEST_NAME: Final[str] = "pose_lifter_manifest.json"
MANIFEST_FORMAT: Final[int] = 1
ERRORS_NAME: Final[str] = "pose_lifter_errors.txt"


class Manifest:
    """``pose_lifter_manifest.json``: what each output was lifted from and with.

    Format (JSON)::

        {"format": 1,
         "settings": {DIGEST: {"version": "0.1.0", "settings": {...LiftSettings...}}},
         "bags": {"rel/path.mcap": {"status": "done" | "failed", "input": "/abs/in.mcap",
                  "input_sha256": HEX, "input_size": N, "input_mtime_ns": N, "settings": DIGEST,
                  "version": "0.1.0", "messages": N, "skeletons": N, "poses": N,
                  "failed_skeletons": N, "seconds": S, "worker": "host:pid", "finished": ISO,
                  "error": TEXT (failed only)}}}
    """

    def __init__(self, out_dir: str | Path) -> None:
        self.path = Path(out_dir) / MANIFEST_NAME
        self.data: dict[str, Any] = {"format": MANIFEST_FORMAT, "settings": {}, "bags": {}}
        if self.path.is_file():
            try:
                loaded = json.loads(self.path.read_text())
            except (OSError, ValueError) as exc:
                raise BagError(f"cannot read the manifest {self.path}: {exc}") from None
            if not isinstance(loaded, dict) or loaded.get("format") != MANIFEST_FORMAT:
                raise BagError(f"{self.path} is not a pose_lifter manifest of format {MANIFEST_FORMAT}")
            self.data = loaded

    def is_done(self, job: BagJob, digest: str, version: str) -> bool:
        """The job's output is there, lifted with these settings from this very input."""
        e = self.data["bags"].get(job.rel)
        if not e or e.get("status") != "done" or e.get("settings") != digest or e.get("version") != version:
            return False
        if not Path(job.output).is_file() or e.get("input") != job.input:
            return False
        if e.get("input_size") == job.size and e.get("input_mtime_ns") == job.mtime_ns:
            return True
        return bool(e.get("input_size") == job.size and e.get("input_sha256") == bag_sha256(job.input))

    def forget(self, rel: str) -> None:
        self.data["bags"].pop(rel, None)

    def record(self, outcome: BagOutcome, digest: str, settings: LiftSettings, version: str) -> None:
        self.data["settings"].setdefault(digest, {"version": version, "settings": settings.to_json()})
        lifted = outcome.lifted  # a failed bag's counts: 0
        n = (0, 0, 0, 0) if lifted is None else (lifted.n_messages, lifted.n_skeletons, lifted.n_lifted,
                                                 lifted.n_failed)
        entry: dict[str, Any] = {
            "status": "failed" if lifted is None else "done", "input": outcome.job.input,
            "input_sha256": outcome.input_sha256, "input_size": outcome.job.size,
            "input_mtime_ns": outcome.job.mtime_ns, "settings": digest, "version": version,
            "messages": n[0], "skeletons": n[1], "poses": n[2], "failed_skeletons": n[3],
            "seconds": round(outcome.seconds, 3),
            "worker": outcome.worker, "finished": datetime.now(UTC).isoformat(timespec="seconds"),
        }
        if lifted is None:
            entry["error"] = outcome.error
        self.data["bags"][outcome.job.rel] = entry
        used = {e.get("settings") for e in self.data["bags"].values()}
        self.data["settings"] = {k: v for k, v in self.data["settings"].items() if k in used}

    def save(self) -> None:
        """Write atomically: a temporary file beside it, renamed over it."""
        tmp = self.path.with_name(f".{self.path.name}.{os.getpid()}.tmp")
        tmp.write_text(json.dumps(self.data, indent=1, sort_keys=True))
        os.replace(tmp, self.path)


# --------------------------------------------------------------------------- one bag


@dataclass
class BagOutcome:
    """What lifting one bag gave (sent back from the worker that lifted it): ``lifted``, what
    :func:`~pose_lifter.offline.lift.lift_bag` did, or None when the bag failed (then ``error`` and
    ``traceback``)."""

    job: BagJob
    lifted: LiftSummary | None = None
    seconds: float = 0.0
    input_sha256: str = ""
    worker: str = ""
    error: str | None = None
    traceback: str | None = None


def lift_one(job: BagJob, settings: LiftSettings, lifter: Any, workers: int = 1) -> BagOutcome:
    """Lift one bag of a collection; any error becomes a failed :class:`BagOutcome` (the output
    then does not exist: nothing half-written is left under its name)."""
    from pose_lifter.offline.lift import lift_bag

    t0 = time.perf_counter()
    worker = f"{os.uname().nodename}:{os.getpid()}"
    try:
        sha = bag_sha256(job.input)
        Path(job.output).parent.mkdir(parents=True, exist_ok=True)
        summary, _ = lift_bag(job.input, job.output, lifter, settings, progress=False, overwrite=True,
                              workers=workers)
    except Exception as exc:  # one bag's failure never stops the collection
        text = " ".join(str(exc).split()) or type(exc).__name__
        if not isinstance(exc, BagError | OSError | ValueError) or type(exc).__module__.startswith("rosbags"):
            text = f"{type(exc).__name__}: {text}"
        return BagOutcome(job, seconds=time.perf_counter() - t0, worker=worker, error=text[:2000],
                          traceback=traceback.format_exc())
    return BagOutcome(job, summary, time.perf_counter() - t0, sha, worker)


# --------------------------------------------------------------------------- executors

#: The lifter and settings the local pool's workers inherit (fork).
_POOL: dict[str, Any] = {}


class _Stopped(SystemExit):
    """SIGTERM in a worker of the local pool (the parent stopping it)."""


def _pool_init(parent: int) -> None:
    """Ctrl-C ends a worker silently (the parent reports it); SIGTERM (the parent stopping the
    pool, :func:`pose_lifter.offline.workers.stop_workers`, or ending: ``die_with_parent``) unwinds
    it, so that the bag it was writing is discarded, and then ends it (:func:`_pool_job`)."""
    from pose_lifter.offline.workers import die_with_parent

    signal.signal(signal.SIGINT, signal.SIG_DFL)

    def stop(signum: int, frame: Any) -> None:
        raise _Stopped(128 + signum)

    signal.signal(signal.SIGTERM, stop)
    die_with_parent(parent)


def _pool_job(job: BagJob) -> BagOutcome:
    try:
        return lift_one(job, _POOL["settings"], _POOL["lifter"])
    except _Stopped as stop:  # unwound (the bag being written discarded): the worker ends here,
        # not in the executor's worker loop, which would return the exception and wait for more
        os._exit(int(stop.code) if isinstance(stop.code, int) else 1)


def _run_local(jobs: list[BagJob], settings: LiftSettings, workers: int, lifter: Any | None,
               on_done: Callable[[BagOutcome], None]) -> None:
    """The local executor: one bag -> its tracks over ``workers`` processes; several bags -> one
    pool of ``min(workers, bags)`` processes started once, a bag per task, largest first."""
    lft = lifter if lifter is not None else settings.build_lifter()
    if len(jobs) == 1 or workers == 1:
        for job in jobs:
            on_done(lift_one(job, settings, lft, workers if len(jobs) == 1 else 1))
        return
    import gc
    import multiprocessing
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

    order = sorted(jobs, key=lambda j: j.size, reverse=True)  # largest first: a short tail
    _POOL.update(settings=settings, lifter=lft)
    gc.freeze()  # the workers' garbage collectors do not walk (and so copy) the parent's objects
    try:
        ex = ProcessPoolExecutor(min(workers, len(jobs)), mp_context=multiprocessing.get_context("fork"),
                                 initializer=_pool_init, initargs=(os.getpid(),))
        try:
            pending = {ex.submit(_pool_job, j) for j in order}
            while pending:
                finished, pending = wait(pending, return_when=FIRST_COMPLETED)
                for fut in finished:
                    on_done(fut.result())
        except BaseException:
            from pose_lifter.offline.workers import stop_workers

            stop_workers(ex)
            raise
        ex.shutdown()
    finally:
        _POOL.clear()
        gc.unfreeze()


_DASK_LOCAL = threading.local()


def _dask_job(job: BagJob, settings: LiftSettings, digest: str) -> BagOutcome:
    """A bag on a Dask worker: the lifter is built once per worker thread and settings digest."""
    from pose_lifter.core.numeric.threads import one_blas_thread

    cache = getattr(_DASK_LOCAL, "lifters", None)
    if cache is None:
        one_blas_thread()
        cache = _DASK_LOCAL.lifters = {}
    if digest not in cache:
        cache.clear()
        cache[digest] = settings.build_lifter()
    return lift_one(job, settings, cache[digest])


def _run_dask(jobs: list[BagJob], settings: LiftSettings, digest: str, address: str,
              on_done: Callable[[BagOutcome], None]) -> None:
    """The Dask executor: one task per bag on the cluster at ``address``."""
    try:
        import distributed
    except ImportError:
        raise BagError("--scheduler needs dask.distributed: pip install 'pose_lifter[cluster]'") from None
    order = sorted(jobs, key=lambda j: j.size, reverse=True)
    dd: Any = distributed  # untyped
    with dd.Client(address, timeout="30s") as client:
        futures = [client.submit(_dask_job, j, settings, digest, pure=False,
                                 key=f"pose-lifter-{hashlib.sha1(j.output.encode()).hexdigest()[:16]}")
                   for j in order]
        try:
            for fut in dd.as_completed(futures):
                on_done(fut.result())
        except BaseException:
            client.cancel(futures)
            raise


# --------------------------------------------------------------------------- the collection


@dataclass
class CollectionSummary:
    """What :func:`lift_collection` did."""

    out_dir: Path
    n_bags: int = 0
    n_lifted: int = 0
    n_skipped: int = 0
    failed: list[BagOutcome] = field(default_factory=list)
    n_poses: int = 0
    n_failed_skeletons: int = 0
    seconds: float = 0.0
    errors_file: Path | None = None

    @property
    def poses_per_s(self) -> float:
        return self.n_poses / self.seconds if self.seconds > 0 else 0.0


def _sweep_partial(out_dir: Path) -> None:
    """Remove the hidden temporary directories a stopped writer left in ``out_dir`` (this run
    owns the directory: one run per output directory at a time)."""
    for d in out_dir.rglob(".bagwriter-*"):
        if d.is_dir():
            shutil.rmtree(d, ignore_errors=True)


def _left_to_lift(planned: list[BagJob], manifest: Manifest, digest: str, version: str, overwrite: bool
                  ) -> list[BagJob]:
    """The jobs of ``planned`` to lift: all with ``overwrite``, else those the manifest does not
    have as done with these settings (``digest``) and this package ``version``; the manifest
    forgets them (saved)."""
    todo = []
    for job in planned:
        if overwrite or not manifest.is_done(job, digest, version):
            manifest.forget(job.rel)
            todo.append(job)
    manifest.save()
    return todo


def _recorder(manifest: Manifest, settings: LiftSettings, digest: str, version: str,
              summary: CollectionSummary, bar: Any, t0: float) -> Callable[[BagOutcome], None]:
    """What is done as each bag ends: its outcome recorded in ``manifest`` (saved, with ``settings``,
    their ``digest`` and the package ``version``) and in ``summary``, the error file in
    ``summary.out_dir`` rewritten if it failed, the progress ``bar`` (tqdm) moved on, its rate
    counted from ``t0`` (``time.perf_counter``)."""
    errors_path = summary.out_dir / ERRORS_NAME

    def on_done(o: BagOutcome) -> None:
        manifest.record(o, digest, settings, version)
        manifest.save()
        if o.lifted is not None:
            summary.n_lifted += 1
            summary.n_poses += o.lifted.n_lifted
            summary.n_failed_skeletons += o.lifted.n_failed
        else:
            summary.failed.append(o)
            _write_errors(errors_path, summary.failed)
        bar.update(1)
        rate = summary.n_poses / max(1e-9, time.perf_counter() - t0)
        bar.set_postfix_str(f"{summary.n_poses} poses, {rate:.0f}/s, {len(summary.failed)} failed")

    return on_done


def lift_collection(
    inputs: Sequence[str],
    out_dir: str | Path,
    settings: LiftSettings,
    *,
    workers: int = 1,
    scheduler: str | None = None,
    overwrite: bool = False,
    progress: bool = True,
    lifter: Any | None = None,
    jobs: Iterable[BagJob] | None = None,
) -> CollectionSummary:
    """Lift the bags named by ``inputs`` into ``out_dir`` (see the module doc).

    Parameters
    ----------
    inputs : sequence of str
        Files, directories and glob patterns (:func:`expand_inputs`).
    out_dir : path
        Created if missing; holds the outputs, the manifest and the error file.
    settings : LiftSettings
    workers : int
        Local processes (ignored with ``scheduler``).
    scheduler : str, optional
        A Dask scheduler's address (``tcp://host:8786``): the bags are lifted on its workers.
    overwrite : bool
        Lift every bag again, even those the manifest has as done with these settings.
    progress : bool
        One tqdm bar over the bags (poses and poses/s beside it).
    lifter : Lifter, optional
        The lifter of ``settings``, when the caller has built it already (local runs only;
        otherwise it is built, its kernels loaded, only when a bag is left to lift).
    jobs : iterable of BagJob, optional
        Planned already (:func:`plan_jobs`); then ``inputs`` is not read.

    Returns
    -------
    CollectionSummary
    """
    from tqdm import tqdm

    t0 = time.perf_counter()
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise BagError(f"--out {out} is a file; a collection is lifted into a directory")
    planned = list(jobs) if jobs is not None else plan_jobs(inputs, out)
    out.mkdir(parents=True, exist_ok=True)
    _sweep_partial(out)
    manifest = Manifest(out)
    version = package_version()
    digest = settings.digest()
    summary = CollectionSummary(out, n_bags=len(planned))
    todo = _left_to_lift(planned, manifest, digest, version, overwrite)
    summary.n_skipped = len(planned) - len(todo)
    errors_path = out / ERRORS_NAME
    bar = tqdm(total=len(todo), desc="bags", unit="bag", disable=not progress, file=sys.stderr)
    on_done = _recorder(manifest, settings, digest, version, summary, bar, t0)
    try:
        if todo:
            if scheduler:
                _run_dask(todo, settings, digest, scheduler, on_done)
            else:
                _run_local(todo, settings, workers, lifter, on_done)
    except BaseException:
        if not scheduler:
            _sweep_partial(out)  # the local workers are stopped: their temporary files are orphans
        raise
    finally:
        bar.close()
    if not summary.failed and errors_path.exists():
        errors_path.unlink()
    summary.errors_file = errors_path if summary.failed else None
    summary.seconds = time.perf_counter() - t0
    return summary


def _write_errors(path: Path, failed: list[BagOutcome]) -> None:
    blocks = [f"== {o.job.input}\n{o.error}\n\n{o.traceback or ''}" for o in failed]
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text("\n".join(blocks))
    os.replace(tmp, path)


def format_summary(s: CollectionSummary) -> str:
    """The collection's summary lines: bags, poses, failed skeletons, poses/s, errors."""
    lines = [
        f"{s.out_dir}: {s.n_bags} bags: {s.n_lifted} lifted, {s.n_skipped} skipped (done already), "
        f"{len(s.failed)} failed",
        f"  {s.n_poses} poses lifted, {s.n_failed_skeletons} skeletons failed, {s.seconds:.1f} s, "
        f"{s.poses_per_s:.0f} poses/s",
    ]
    for o in s.failed[:10]:
        lines.append(f"  failed: {o.job.input}: {o.error}")
    if len(s.failed) > 10:
        lines.append(f"  ... and {len(s.failed) - 10} more")
    if s.errors_file is not None:
        lines.append(f"  errors and tracebacks: {s.errors_file}")
    lines.append(f"  manifest: {s.out_dir / MANIFEST_NAME}")
    return "\n".join(lines)
