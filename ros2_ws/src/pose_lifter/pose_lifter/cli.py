"""``pose-lifter``: offline commands (learn bases, make bags, lift, export, play, evaluate, demo).

Run ``pose-lifter --help`` or ``python -m pose_lifter.cli --help``.

Exit codes: 0 success; 2 a usage error (an option out of range, a missing input file or data
directory, an output that exists or is a directory) and every other library error; 1 a data
error (a corrupt, truncated, empty or foreign bag, an invalid basis file, input with nothing to
lift, a solve that diverged on the input); 130 interrupted (Ctrl-C); 143 terminated (SIGTERM). Each
failure prints one ``pose-lifter <cmd>: error: ...`` line and leaves no partial output file (set
``POSE_LIFTER_DEBUG=1`` for the traceback) and no worker process behind it.
"""

from __future__ import annotations

import argparse
import gc
import os
import shlex
import signal
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Final, Literal

from pose_lifter.core.track.smoothing import OFFLINE_SMOOTHING_S
from pose_lifter.messages.names import TOPIC_CAMERA_INFO, TOPIC_KEYPOINTS, TOPIC_SKELETONS
from pose_lifter.offline.arg_types import FINITE, FRACTION, NONNEG, POS_INT, POSITIVE, number

__all__ = ["build_parser", "main", "make_bag"]


def _out_is_a_directory(args: argparse.Namespace) -> bool:
    """An output file path must not name a directory (it would be written inside it)."""
    out = getattr(args, "out", None)
    if args.cmd == "lift" and _is_collection(args):
        return False
    return args.cmd in ("lift", "make-bag", "learn-bases") and out is not None and Path(out).is_dir()


#: Errors that mean the input data is bad (exit code 1); see the module doc.
def _is_data_error(exc: BaseException) -> bool:
    from pose_lifter.core.errors import BasisFileError, InvalidInputError, SolverError
    from pose_lifter.offline.bags import BagReadError

    return (isinstance(exc, BasisFileError | InvalidInputError | BagReadError | SolverError)
            or type(exc).__module__.startswith("rosbags"))


def _command_line(argv: Sequence[str] | None) -> str:
    args = list(sys.argv[1:] if argv is None else argv)
    return shlex.join(["pose-lifter", *args])


# --------------------------------------------------------------------------- learn-bases


def _cmd_learn_bases(args: argparse.Namespace) -> int:
    import time

    from pose_lifter.mocap.bases_training import learn_bases

    t0 = time.perf_counter()
    bases = learn_bases(args.method, args.n_bases, args.data, args.step, args.sparsity, args.starts,
                        args.n_per_class, args.seed, args.n_iter, args.command, args.split, args.limb_spread)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    bases.save(out)
    print(f"{bases.method}: {bases.n_bases} bases from {bases.metadata['n_training_poses']} poses "
          f"of {len(bases.metadata['training_trials'])} trials in {time.perf_counter() - t0:.1f} s -> {out}")
    return 0


# --------------------------------------------------------------------------- make-bag


def make_bag(
    trials: Sequence[str], out: str | Path, data_dir: str | Path | None = None, fps: float = 30.0,
    start: float = 0.0, frames: int | None = None, overwrite: bool = False,
    depth: Literal["raw", "compressed"] | None = None, one_after_another: bool = False,
    camera_info: bool = True, one_track: bool = False,
    **scene: Any,
) -> Any:
    """Film mocap trials with the virtual camera and write the bag.

    Parameters
    ----------
    trials : sequence of str
        One trial per person (track ids 0, 1, ...), side by side or ``one_after_another``
        (:func:`pose_lifter.mocap.scenes.film_trials`).
    out : path
        ``.mcap`` file.
    data_dir : path, optional
    fps : float
    start : float
        Seconds into each trial.
    frames : int, optional
        Output frames of each trial (default: all; side by side, the shortest trial's).
    depth : {"raw", "compressed"}, optional
        Also film the depth image of each frame (:func:`pose_lifter.mocap.scenes.scene_messages`):
        16UC1 ``sensor_msgs/Image`` or its compressedDepth PNG.
    camera_info : bool
        Write ``/camera_info`` (False: the bag has none).
    one_track : bool
        With ``one_after_another``: the trials as one track, a frame apart.
    **scene
        Other :class:`pose_lifter.mocap.scenes.SceneOptions` fields.

    Returns
    -------
    list of Scene
    """
    from pose_lifter.mocap import cmu as mocap
    from pose_lifter.mocap import scenes
    from pose_lifter.offline.bags import write_messages

    opts = scenes.SceneOptions(fps=fps, **scene)
    filmed = scenes.film_trials(trials, mocap.resolve_data_dir(data_dir), opts, start, frames,
                                one_after_another, one_track)
    write_messages(out, (x for f in filmed for x in scenes.scene_messages(f, depth, camera_info)),
                   overwrite=overwrite)
    return filmed


def _cmd_make_bag(args: argparse.Namespace) -> int:
    filmed = make_bag(
        args.trials, args.out, args.data, fps=args.fps, start=args.start, frames=args.frames,
        overwrite=args.overwrite, view_angle=args.view_angle, orbit_speed=args.orbit_speed,
        distance=args.distance, follow=not args.no_follow, spacing=args.spacing, noise=args.noise,
        outliers=args.outliers, missing=args.missing, seed=args.seed,
        depth=args.depth_format if args.depth else None, one_after_another=args.one_after_another,
        camera_info=not args.no_camera_info, one_track=args.one_track)
    rgbd = f", depth {args.depth_format}" if args.depth else ""
    print(f"{args.out}: {sum(s.joints_camera.shape[1] for s in filmed)} frames at {args.fps:g} Hz, "
          f"tracks {[t for s in filmed for t in s.track_ids]}{rgbd}")
    return 0


# --------------------------------------------------------------------------- lift / evaluate


def _cores() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def _params(args: argparse.Namespace) -> dict[str, Any] | None:
    """The ``--params-file`` read (:func:`pose_lifter.messages.settings.read_params_file`), or None."""
    from pose_lifter.messages.settings import read_params_file

    return read_params_file(args.params_file) if args.params_file else None


def _is_collection(args: argparse.Namespace) -> bool:
    """Several inputs, a directory of bags or a glob pattern: a collection, lifted into a
    directory. A rosbag2 directory (or its ``metadata.yaml``) is one bag: lifted into ``--out``
    when that names a ``.mcap`` file, else as a collection of one into the directory ``--out``."""
    from pose_lifter.offline.bags import bag_path, is_rosbag2_dir
    from pose_lifter.offline.collection import is_pattern

    inputs = list(args.input)
    if len(inputs) > 1:
        return True
    (text,) = inputs
    if is_pattern(text) and not Path(text).exists():
        return True
    if is_rosbag2_dir(bag_path(text)):
        return Path(args.out).suffix != ".mcap"
    return Path(text).is_dir()


def _cmd_lift(args: argparse.Namespace) -> int:
    if _is_collection(args):
        return _cmd_lift_collection(args)
    if args.scheduler:
        raise ValueError("--scheduler lifts a collection: name several bags, a directory or a glob, "
                         "and --out a directory")
    from pose_lifter.offline.bags import BagError
    from pose_lifter.offline.flags import keep_topics, lift_settings
    from pose_lifter.offline.lift import FirstPassPlan, check_lift_inputs, lift_bag, read_ahead

    (bag,) = args.input
    keep = keep_topics(args.keep)
    camera_info = args.camera_info_topic or None
    # every check that needs no lifting first: bad input never costs a kernel compile
    topics = check_lift_inputs(bag, args.out, args.topic, camera_info, keep, args.overwrite, args.depth_topic)
    if camera_info and camera_info not in topics and "camera_info_topic" in args.typed:
        raise BagError(f"{bag} has no topic {camera_info!r}; its topics: {sorted(topics)} "
                       "(--camera-info-topic '' lifts without camera_info, at the default distance)")
    s = lift_settings(args, _params(args))
    if camera_info and camera_info not in topics:  # the default topic, absent: as the node without it
        print(f"pose-lifter lift: note: {bag} has no {camera_info}: depth at the default distance, "
              f"{s.frame.default_distance:g} m (--camera-info-topic names another topic)", file=sys.stderr)
    with read_ahead(bag, FirstPassPlan.of(bag, s, topics)) as ahead:  # beside the kernels' loading
        summary, _ = lift_bag(bag, args.out, s.build_lifter(), s, progress=not args.quiet,
                              overwrite=args.overwrite, workers=args.workers or _cores(), first_pass=ahead)
    print(f"{args.out}: lifted {summary.n_lifted} of {summary.n_skeletons} skeletons in "
          f"{summary.n_messages} messages ({summary.n_warm} warm-started, {summary.n_failed} failed), "
          f"{summary.mean_solve_time_ms:.1f} ms per skeleton")
    for line in [f"failed: {f}" for f in summary.failures[:5]] + summary.notes:
        print(f"  {line}")
    return 0


def _cmd_lift_collection(args: argparse.Namespace) -> int:
    from pose_lifter.offline.bags import BagError
    from pose_lifter.offline.collection import format_summary, lift_collection, plan_jobs
    from pose_lifter.offline.flags import lift_settings

    out = Path(args.out)
    if out.suffix == ".mcap" and not out.is_dir():
        raise BagError(f"a collection is lifted into a directory: --out {out} names a .mcap file")
    jobs = plan_jobs(args.input, out)  # every input found before any work
    settings = lift_settings(args, _params(args))
    summary = lift_collection(args.input, out, settings, workers=args.workers or _cores(),
                              scheduler=args.scheduler, overwrite=args.overwrite, progress=not args.quiet,
                              jobs=jobs)
    print(format_summary(summary))
    return 1 if summary.failed else 0


def _cmd_export(args: argparse.Namespace) -> int:
    from pose_lifter.offline.export import export_skeletons

    n_msgs, n_skels = export_skeletons(args.bag, args.out, args.topic, args.overwrite)
    print(f"{args.out}: {n_skels} skeletons of {n_msgs} messages of {args.topic}")
    return 0


def _cmd_play(args: argparse.Namespace) -> int:
    from pose_lifter.ros.play import play_bag

    try:
        play_bag(args.bag, args.topics, args.rate, args.wait)
    except KeyboardInterrupt:
        return 130
    return 0


def _cmd_evaluate(args: argparse.Namespace) -> int:
    from pose_lifter.core.model.bases import PoseBases
    from pose_lifter.offline.evaluate import evaluate_bag, format_evaluation

    ev = evaluate_bag(args.bag, PoseBases.load(args.bases))
    print(format_evaluation(ev, as_json=args.json))
    if ev.n_estimates == 0:  # an unlifted bag: its floors only
        print(f"pose-lifter evaluate: {args.bag} has no estimates: only the floors of its 2D are measured; "
              "lift it first (pose-lifter lift) to evaluate a lifter", file=sys.stderr)
    elif ev.n_matched == 0:  # estimates of other stamps or tracks: nothing to compare
        print(f"pose-lifter evaluate: error: none of the {ev.n_estimates} estimates of {args.bag} matches "
              "a ground-truth skeleton (stamp and track)", file=sys.stderr)
        return 1
    return 0


def _cmd_demo(args: argparse.Namespace) -> int:
    from pose_lifter.offline.demo import run_demo
    from pose_lifter.offline.flags import lift_settings

    # the lift `pose-lifter lift BAG` does by default (every frame, the node's settings, centred
    # smoothing)
    settings = lift_settings(args)
    return run_demo(settings.build_lifter, settings, args.out, args.bag, workers=_cores())


# --------------------------------------------------------------------------- parser


def _cmd_experiments(args: argparse.Namespace) -> int:
    from pose_lifter.mocap.experiments import run_experiments

    run_experiments(args.data, args.out, quick=args.quick, processes=args.processes, command=args.command)
    return 0


def _cmd_warm_up(args: argparse.Namespace) -> int:
    from pose_lifter.core.lift.lifter import KERNEL_MODES
    from pose_lifter.core.numeric.jit import HAVE_NUMBA
    from pose_lifter.core.track.policy import compile_kernels

    seconds = compile_kernels()
    state = "compiled or loaded" if HAVE_NUMBA else "not compiled (numba is not installed)"
    print(f"pose-lifter warm-up: solver kernels of the {' and '.join(KERNEL_MODES)} modes {state} "
          f"in {seconds:.1f} s")
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The ``pose-lifter`` argument parser."""
    return _build_parsers()[0]


#: The value of every option not typed, in :func:`_typed_options`' second parse.
_NOT_TYPED: Final[object] = object()


def _typed_options(argv: Sequence[str] | None, args: argparse.Namespace) -> frozenset[str]:
    """The options (``dest`` names) typed on the command line of ``args.cmd``, whatever their
    value: ``--n-starts 30`` is typed even where 30 is the default (so it wins over a params file).

    The command line is parsed again with every default of the command set to a marker; argparse
    resolves abbreviations and ``--opt=value`` forms as in the first parse."""
    parser, commands = _build_parsers()
    commands[args.cmd].set_defaults(**{dest: _NOT_TYPED for dest in vars(args) if dest != "cmd"})
    again = parser.parse_args(argv)
    return frozenset(k for k, v in vars(again).items() if v is not _NOT_TYPED and k != "cmd")


def _learn_bases_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The ``pose-lifter learn-bases`` command's arguments."""
    p = sub.add_parser("learn-bases", help="learn pose bases from the paper's CMU training split")
    p.add_argument("--data", default=None, help="CMU data dir (default ../shared/data/cmu or "
                   "$POSE_LIFTER_CMU_DATA)")
    p.add_argument("--method", choices=("sparse", "pca", "classwise-pca"), default="sparse")
    p.add_argument("--n-bases", type=POS_INT, default=None, help="default 200 (sparse), 30 (pca)")
    p.add_argument("--sparsity", type=POSITIVE, default=0.1, help="L1 weight of sparse learning")
    p.add_argument("--n-per-class", type=POS_INT, default=6, help="classwise-pca components per class")
    p.add_argument("--step", type=POS_INT, default=8,
                   help="use every STEP-th 120 Hz frame (default 8: 15 Hz)")
    p.add_argument("--starts", type=POS_INT, default=30, help="multi-start poses stored (k-means + mean)")
    p.add_argument("--n-iter", type=POS_INT, default=2000, help="dictionary-learning iterations")
    p.add_argument("--split", choices=("paper", "prior"), default="paper",
                   help="paper: subject 01 playground (the paper's protocol); prior: the trials the "
                        "packaged learned prior was trained on (the product's hybrid bases)")
    p.add_argument("--limb-spread", type=FRACTION, default=0.0,
                   help="scale each frame's limbs by up to +-this fraction first (other proportions)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", required=True, help="output .npz")
    p.set_defaults(func=_cmd_learn_bases)


def _make_bag_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The ``pose-lifter make-bag`` command's arguments."""
    p = sub.add_parser("make-bag", help="film mocap trials with a virtual camera into an MCAP bag")
    p.add_argument("trials", nargs="+", help="one trial id per person, e.g. 07_05 02_05")
    p.add_argument("--out", required=True, help="output .mcap")
    p.add_argument("--data", default=None, help="CMU data dir")
    p.add_argument("--fps", type=number(float, 0.0, 1000.0, low_open=True), default=30.0,
                   help="frame rate (mocap is 120 Hz)")
    p.add_argument("--start", type=NONNEG, default=0.0, help="seconds into each trial")
    p.add_argument("--frames", type=POS_INT, default=None, help="number of frames (default: all)")
    p.add_argument("--view-angle", type=FINITE, default=0.0,
                   help="degrees about the vertical axis from the first person's initial facing "
                   "direction (0 = front, 90 = their left side, 180 = behind)")
    p.add_argument("--orbit-speed", type=FINITE, default=0.0, help="camera orbit, degrees per second")
    p.add_argument("--distance", type=POSITIVE, default=5.0, help="camera distance in metres")
    p.add_argument("--no-follow", action="store_true", help="static camera (default: slides with the people)")
    p.add_argument("--spacing", type=NONNEG, default=1.4, help="metres between people")
    p.add_argument("--noise", type=NONNEG, default=0.0, help="2D Gaussian noise std, right-lower-leg units")
    p.add_argument("--outliers", type=FRACTION, default=0.0, help="fraction of joints displaced 1-3 legs")
    p.add_argument("--missing", type=FRACTION, default=0.0, help="fraction of joints with confidence 0")
    p.add_argument("--seed", type=int, default=0, help="seed of the 2D corruption and the depth sensor")
    p.add_argument("--depth", action="store_true",
                   help="RGB-D: also each frame's depth image, the body surface seen by a D435-like sensor "
                   "(pose_lifter.mocap.depth_model), registered to the virtual camera")
    p.add_argument("--depth-format", choices=("raw", "compressed"), default="raw",
                   help="raw: 16UC1 sensor_msgs/Image (mm) on the depth topic; compressed: image_transport's "
                   "compressedDepth PNG on its /compressedDepth topic")
    p.add_argument("--one-after-another", action="store_true", help="the trials one at a time, each its own "
                   "track, a second apart (default: side by side, all at once)")
    p.add_argument("--one-track", action="store_true", help="with --one-after-another: the trials as one "
                   "track, a frame apart (one person recorded at length)")
    p.add_argument("--no-camera-info", action="store_true", help="leave /camera_info out")
    p.add_argument("--overwrite", action="store_true")
    p.set_defaults(func=_cmd_make_bag)


def _lift_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The ``pose-lifter lift`` command's arguments."""
    from pose_lifter.offline.flags import add_parameter_flags

    p = sub.add_parser("lift", help="lift every /keypoints_2d message of a bag, or of a collection of bags")
    p.add_argument("input", nargs="+",
                   help="input bag: a .mcap file or a rosbag2 directory (a folder with metadata.yaml, "
                   "as ros2 bag record writes it; its split files are one recording; the directory or "
                   "its metadata.yaml); or several, directories of bags (searched recursively) and "
                   "glob patterns (a collection, lifted into the directory --out)")
    p.add_argument("--out", required=True,
                   help="output .mcap (input topics + /skeletons_3d + markers); for a collection (or "
                   "one rosbag2 directory and --out not a .mcap) a directory: one output per input "
                   "(a rosbag2 directory NAME: NAME.mcap) with the inputs' relative layout, a manifest "
                   "(pose_lifter_manifest.json) that lets a stopped run resume")
    add_parameter_flags(p)
    p.add_argument("--every", type=POS_INT, default=1, help="lift every N-th message only")
    p.add_argument("--max-messages", type=POS_INT, default=None, help="stop after N lifted messages")
    p.add_argument("--smoothing", type=number(float, 0.0, 10.0), default=OFFLINE_SMOOTHING_S,
                   metavar="SECONDS",
                   help="each track's poses smoothed by a centred Gaussian window of this standard "
                   "deviation, past and future frames alike (offline only; default "
                   f"{OFFLINE_SMOOTHING_S}); 0: the live node's causal poses, message for message")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--overwrite", action="store_true",
                   help="replace the output; for a collection: lift again the bags already done")
    p.add_argument("--workers", type=POS_INT, default=None,
                   help="processes lifting the tracks (one bag) or the bags (a collection) in parallel "
                   "(results identical to 1; default: the cores available)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="lift a collection on a Dask distributed cluster (e.g. tcp://host:8786; needs "
                   "the 'cluster' extra): one task per bag; inputs and outputs on a file system every "
                   "worker sees under the same paths")
    p.add_argument("--topic", default=TOPIC_KEYPOINTS,
                   help="keypoints: pose_lifter_msgs/Skeleton2DArray or yolo_msgs/DetectionArray "
                   f"(default {TOPIC_KEYPOINTS})")
    p.add_argument("--camera-info-topic", default=TOPIC_CAMERA_INFO,
                   help="sensor_msgs/CameraInfo for the metric depth "
                   f"('' = none; default {TOPIC_CAMERA_INFO})")
    p.add_argument("--keep", nargs="+", default=None, metavar="TOPIC",
                   help="input topics copied to the output: 'all' (default), 'none', or topic names")
    p.add_argument("--params-file", default=None,
                   help="the node's params YAML (config/lifter.yaml): lift with the live node's parameters; "
                   "a flag typed on the command line wins over the file; a key the offline lift cannot "
                   "honour (a parameter of the live node only, at another value than its default, or an "
                   "unknown name) is an error")
    p.set_defaults(func=_cmd_lift)


def _lifted_bag_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser], name: str,
                       summary: str) -> argparse.ArgumentParser:
    """The parser of a command ``name`` (``summary``: its line in the commands' list) that reads a
    lifted bag, its first argument."""
    p = sub.add_parser(name, help=summary)
    p.add_argument("bag", help="a lifted bag: .mcap file or rosbag2 directory")
    return p


def _export_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The ``pose-lifter export`` command's arguments."""
    p = _lifted_bag_parser(sub, "export", "the /skeletons_3d of a bag as CSV, NPZ or JSON")
    p.add_argument("--out", required=True, help="output file: .csv, .npz or .json (format from the suffix)")
    p.add_argument("--topic", default=TOPIC_SKELETONS,
                   help=f"Skeleton3DArray topic (default {TOPIC_SKELETONS})")
    p.add_argument("--overwrite", action="store_true")
    p.set_defaults(func=_cmd_export)


def _evaluate_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The ``pose-lifter evaluate`` command's arguments."""
    p = _lifted_bag_parser(sub, "evaluate", "errors of /skeletons_3d against /ground_truth/skeletons_3d")
    p.add_argument("--bases", default=None, help="bases for the mean-pose floor (default: packaged)")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=_cmd_evaluate)


def _play_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The ``pose-lifter play`` command's arguments."""
    p = sub.add_parser("play", help="publish a bag's topics into the live ROS graph at the bag's rate")
    p.add_argument("bag", help="input bag: .mcap file or rosbag2 directory")
    p.add_argument("--topics", nargs="+", default=None, metavar="TOPIC", help="only these topics")
    p.add_argument("--rate", type=float, default=1.0, help="speed factor (default 1: real time)")
    p.add_argument("--wait", type=NONNEG, default=5.0, metavar="SECONDS",
                   help="before the first message, wait up to SECONDS for a subscriber on the played "
                   "topics a lifter reads (keypoints, camera_info; the ground truth is not waited for), "
                   "so that no first message is lost; on giving up, one line on stderr and play "
                   "(default 5; 0: do not wait)")
    p.set_defaults(func=_cmd_play)


def _demo_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The ``pose-lifter demo`` command's arguments."""
    from pose_lifter.offline.flags import add_parameter_flags

    p = sub.add_parser("demo", help="lift a committed bag, print errors, write out/demo.mcap + out/demo.png")
    p.add_argument("--bag", default=None, help="input bag (default: the committed two-person bag)")
    p.add_argument("--out", default="out", help="output directory")
    add_parameter_flags(p)
    p.add_argument("--every", type=POS_INT, default=1, help="lift every N-th frame (default 1: all)")
    p.add_argument("--smoothing", type=number(float, 0.0, 10.0), default=OFFLINE_SMOOTHING_S,
                   metavar="SECONDS", help=f"as for lift (default {OFFLINE_SMOOTHING_S})")
    p.set_defaults(func=_cmd_demo)


def _experiments_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The ``pose-lifter experiments`` command's arguments."""
    p = sub.add_parser("experiments", help="the paper's experiments (Sec. 4) on CMU data -> PNG/CSV/markdown")
    p.add_argument("--data", default=None, help="CMU data dir (default ../shared/data/cmu or "
                   "$POSE_LIFTER_CMU_DATA)")
    p.add_argument("--out", default="out/experiments", help="output directory")
    p.add_argument("--quick", action="store_true", help="a tiny run (a couple of poses) for tests")
    p.add_argument("--processes", type=POS_INT, default=2, help="worker processes (default 2)")
    p.set_defaults(func=_cmd_experiments)


def _build_parsers() -> tuple[argparse.ArgumentParser, dict[str, argparse.ArgumentParser]]:
    """The ``pose-lifter`` parser and its commands' parsers (name -> parser)."""
    parser = argparse.ArgumentParser(
        prog="pose-lifter", description="Offline commands: learn bases, make bags, lift bags, evaluate, demo."
    )
    parser.add_argument("--version", action="version", version=f"pose-lifter {_version()}")
    sub = parser.add_subparsers(dest="cmd", required=True, metavar="COMMAND")

    _learn_bases_parser(sub)
    _make_bag_parser(sub)
    _lift_parser(sub)
    _export_parser(sub)
    _play_parser(sub)
    _evaluate_parser(sub)
    _demo_parser(sub)
    _experiments_parser(sub)
    p = sub.add_parser("warm-up", help="compile the solver kernels into the package's cache (make venv does)")
    p.set_defaults(func=_cmd_warm_up)
    return parser, dict(sub.choices)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``pose-lifter`` console script (``argv`` None: the process's arguments;
    the process then ends right after, see :func:`_main`)."""
    if argv is None:
        # the start-up (numba's import, the kernels' loading) makes ~120,000 objects that live as
        # long as the process and almost no garbage; at the default threshold (700) the collector
        # runs ~290 times on the way, walking them (0.05-0.06 s of a ~1 s start-up). The lift
        # itself measures the same at either threshold.
        gc.set_threshold(100_000, 50, 100)
        # SIGTERM (a supervisor, `timeout`) stops a command as Ctrl-C does, its workers with it
        signal.signal(signal.SIGTERM, _terminated)
    try:
        rc = _main(argv)
    except Terminated:  # before or after its command ran (the command's own: in _main)
        print("pose-lifter: terminated", file=sys.stderr)
        rc = 143
    if argv is None:
        # the interpreter's last garbage collections at exit walk every object the command made
        # (the bag's messages, the results: ~1 s after lifting a 36-track bag); frozen, they are
        # skipped. Files, pools and progress bars are closed by now; the process's memory goes
        # back when it ends.
        gc.freeze()
    return rc


class Terminated(BaseException):
    """SIGTERM in the ``pose-lifter`` process: raised where it is, unwound as Ctrl-C is (a pool's
    workers stopped, no partial output), exit 143."""


def _terminated(signum: int, frame: Any) -> None:
    raise Terminated(signum)


def _version() -> str:
    """The installed package's version (``setup.py``), or ``unknown`` when it is not installed."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("pose_lifter")
    except PackageNotFoundError:
        return "unknown"


def _main(argv: Sequence[str] | None) -> int:
    from pose_lifter.core.numeric.threads import one_blas_thread

    one_blas_thread()  # small matrices: BLAS threads only contend (worker processes inherit it)
    parser = build_parser()
    if not (sys.argv[1:] if argv is None else list(argv)):  # a bare `pose-lifter`: what it can do
        parser.print_help()
        return 0
    args = parser.parse_args(argv)
    if _out_is_a_directory(args):
        print(f"pose-lifter {args.cmd}: error: --out {args.out} is a directory; name the output file",
              file=sys.stderr)
        return 2
    args.command = _command_line(argv)
    args.typed = _typed_options(argv, args)
    try:
        rc = int(args.func(args))
        sys.stdout.flush()  # here, where a reader that went away is answered (below)
        return rc
    except KeyboardInterrupt:
        print(f"pose-lifter {args.cmd}: interrupted", file=sys.stderr)
        return 130
    except Terminated:
        print(f"pose-lifter {args.cmd}: terminated", file=sys.stderr)
        return 143
    except BrokenPipeError:  # the reader went away (`pose-lifter evaluate X | head -1`): as SIGPIPE
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # the interpreter's final flush has nowhere to fail
        return 141
    except Exception as exc:
        if os.environ.get("POSE_LIFTER_DEBUG"):
            raise
        text = " ".join(str(exc).split()) or type(exc).__name__
        if type(exc).__module__.startswith("rosbags") or not isinstance(exc, _library_errors()):
            text = f"{type(exc).__name__}: {text}"
        print(f"pose-lifter {args.cmd}: error: {text[:2000]}", file=sys.stderr)
        return 1 if _is_data_error(exc) else 2


def _library_errors() -> tuple[type[BaseException], ...]:
    from pose_lifter.core.errors import PoseLifterError

    return (PoseLifterError, OSError, ValueError)


if __name__ == "__main__":
    sys.exit(main())
