"""``pose-lifter demo``: lift a committed bag, print its error table, write an MCAP and a PNG.

The bag is lifted as ``pose-lifter lift BAG`` lifts it by default. The PNG shows three frames:
the 2D keypoints the lifter got (left) beside the lifted 3D skeletons and the ground truth in
the camera frame (right); one colour per track, the person's left limbs in full colour and the
right ones lighter.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

import numpy as np
from numpy.typing import NDArray

from pose_lifter.core.model.skeleton import BONES_FOR_DRAWING, JOINTS_LEFT, JOINTS_RIGHT

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure
    from mpl_toolkits.mplot3d.axes3d import Axes3D

    from pose_lifter.core.lift.lifter import Lifter
    from pose_lifter.offline.settings import LiftSettings

__all__ = ["DEFAULT_DEMO_BAG", "find_demo_bag", "plot_frames", "run_demo"]

#: The committed bag the demo lifts by default (two people, tracks 0 and 1).
DEFAULT_DEMO_BAG: Final[str] = "two_people.mcap"


def find_demo_bag(name: str = DEFAULT_DEMO_BAG) -> Path:
    """The committed bag ``bags/<name>`` of the source tree (or ``./bags/<name>``)."""
    for root in (Path(__file__).resolve().parents[5], Path.cwd()):
        p = root / "bags" / name
        if p.is_file():
            return p
    raise FileNotFoundError(f"bags/{name} not found next to the package or in the working directory; "
                            "pass --bag PATH")


def _side_shade(a: int, b: int) -> float:
    """How much a bone's colour is lightened: 0 for the person's left limbs, 0.55 for the right
    ones, between for the bones across the torso."""
    if a in JOINTS_LEFT and b in JOINTS_LEFT:
        return 0.0
    if a in JOINTS_RIGHT and b in JOINTS_RIGHT:
        return 0.55
    return 0.3


def _lighter(colour: tuple[float, ...], amount: float) -> tuple[float, float, float]:
    """``colour`` mixed with white by ``amount`` (0: unchanged)."""
    r, g, b = colour[:3]
    return (r + (1 - r) * amount, g + (1 - g) * amount, b + (1 - b) * amount)


def _to_plot(points_cam: NDArray[np.float64]) -> NDArray[np.float64]:
    """Camera optical frame (x right, y down, z forward) -> plot axes (x right, depth, up)."""
    p = np.asarray(points_cam)
    return np.stack([p[..., 0], p[..., 2], -p[..., 1]], axis=-1)


def plot_frames(
    frames: list[dict[str, Any]], path: str | Path, title: str = "", image_size: tuple[int, int] = (640, 480)
) -> None:
    """Draw frames side by side and save a PNG.

    One row per frame: the 2D input (left) and, larger, the lifted 3D skeletons with the ground
    truth (right). Each track has its colour (a legend names them); the person's left limbs are
    drawn in full colour, the right ones lighter; the ground truth is grey and dashed.

    Parameters
    ----------
    frames : list of dict
        Each with ``stamp_ns`` and ``people``: a list of dicts with ``track_id``,
        ``points_2d`` (12, 2) pixels, ``confidence`` (12,), ``lifted`` (12, 3) metres and
        optionally ``truth`` (12, 3) metres (camera optical frame).
    path : path
    title : str
    image_size : (width, height)
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from pose_lifter.messages.convert import track_color

    n = len(frames)
    fig = plt.figure(figsize=(12.0, 4.8 * n + 0.6))
    grid = fig.add_gridspec(n, 2, width_ratios=(1.0, 1.7))
    tracks: set[int] = set()
    for row, fr in enumerate(frames):
        ax2 = fig.add_subplot(grid[row, 0])
        ax3 = fig.add_subplot(grid[row, 1], projection="3d")
        t = (fr["stamp_ns"] - frames[0]["stamp_ns"]) * 1e-9
        everything = []
        for person in fr["people"]:
            tracks.add(int(person["track_id"]))
            everything += _draw_person(ax2, ax3, person, track_color(int(person["track_id"])))
        _frame_axes(ax2, ax3, everything, image_size, t)
    _legend_and_layout(fig, tracks, title)
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _draw_person(ax2: Axes, ax3: Axes3D, person: dict[str, Any], colour: tuple[float, ...]
                 ) -> list[NDArray[np.float64]]:
    """One person of a frame: the bones and visible joints of ``points_2d`` (12, 2) in ``ax2``, the
    skeletons ``truth`` (dashed) and ``lifted`` (12, 3 each, camera frame) in ``ax3``. Returns those
    skeletons in plot axes, each (12, 3)."""
    drawn = []
    pts, conf = person["points_2d"], person["confidence"]
    for a, b in BONES_FOR_DRAWING:
        if conf[a] > 0 and conf[b] > 0:
            ax2.plot([pts[a, 0], pts[b, 0]], [pts[a, 1], pts[b, 1]], lw=2,
                     color=_lighter(colour, _side_shade(a, b)))
    vis = conf > 0
    ax2.scatter(pts[vis, 0], pts[vis, 1], s=10, color=colour)
    for key, style in (("truth", "--"), ("lifted", "-")):
        if person.get(key) is None:
            continue
        q = _to_plot(person[key])
        drawn.append(q)
        for a, b in BONES_FOR_DRAWING:
            base = (0.3, 0.3, 0.3) if key == "truth" else colour
            ax3.plot(*zip(q[a], q[b], strict=True), ls=style, lw=1.2 if style == "--" else 2.4,
                     color=_lighter(base, _side_shade(a, b)))
    return drawn


def _frame_axes(ax2: Axes, ax3: Axes3D, everything: list[NDArray[np.float64]], image_size: tuple[int, int],
                t: float) -> None:
    """Limits, labels and titles of one frame's axes: ``ax2`` the image of ``image_size`` (width,
    height), ``ax3`` a cube around the skeletons ``everything`` (each (12, 3), plot axes); ``t`` is
    the frame's time in seconds."""
    from matplotlib.ticker import MaxNLocator

    ax2.set_xlim(0, image_size[0])
    ax2.set_ylim(image_size[1], 0)
    ax2.set_aspect("equal")
    ax2.set_title(f"2D input (pixels), t = {t:.2f} s", fontsize=9)
    if everything:
        allp = np.concatenate(everything)
        centre = 0.5 * (allp.max(axis=0) + allp.min(axis=0))
        half = 0.55 * float(np.max(allp.max(axis=0) - allp.min(axis=0)))
        for setter, c in zip((ax3.set_xlim, ax3.set_ylim, ax3.set_zlim), centre, strict=True):
            setter(c - half, c + half)
    ax3.set_box_aspect((1, 1, 1), zoom=1.1)
    ax3.view_init(elev=15, azim=-78)
    for axis in (ax3.xaxis, ax3.yaxis, ax3.zaxis):
        axis.set_major_locator(MaxNLocator(4))
    ax3.set_xlabel("x (m)", fontsize=8)
    ax3.set_ylabel("depth (m)", fontsize=8)
    ax3.set_zlabel("up (m)", fontsize=8)
    ax3.tick_params(labelsize=7)
    ax3.set_title(f"lifted 3D vs ground truth (camera frame), t = {t:.2f} s", fontsize=9)


def _legend_and_layout(fig: Figure, tracks: set[int], title: str) -> None:
    """The legend (a colour per track in ``tracks``, the limb sides, the ground truth), the title
    and the margins of ``fig``."""
    from matplotlib.lines import Line2D

    from pose_lifter.messages.convert import track_color

    handles = [Line2D([], [], color=track_color(k), lw=2.4, label=f"track {k}") for k in sorted(tracks)]
    grey = (0.3, 0.3, 0.3)
    handles += [Line2D([], [], color=grey, lw=2.4, label="left limbs"),
                Line2D([], [], color=_lighter(grey, 0.55), lw=2.4, label="right limbs (lighter)"),
                Line2D([], [], color=grey, lw=1.2, ls="--", label="ground truth (3D)")]
    fig.legend(handles=handles, loc="upper center", ncol=len(handles), fontsize=9, frameon=False,
               bbox_to_anchor=(0.5, 1.0 - 0.25 / fig.get_figheight()))
    if title:
        fig.suptitle(title, fontsize=11, y=1.0 - 0.02 / fig.get_figheight())
    height = fig.get_figheight()
    fig.subplots_adjust(left=0.05, right=0.96, bottom=0.3 / height, top=1.0 - 1.0 / height, wspace=0.08,
                        hspace=0.22)


def run_demo(make_lifter: Callable[[], Lifter], settings: LiftSettings, out: str | Path,
             bag: str | Path | None = None, workers: int = 1) -> int:
    """Lift the demo bag, print the error table, write ``out/demo.mcap`` and ``out/demo.png``.

    Parameters
    ----------
    make_lifter : callable
        Builds the lifter, called once the bag is found (a kernel compile is not wasted on a
        missing bag).
    settings : LiftSettings
        The lift's settings, as for :func:`pose_lifter.offline.lift.lift_bag` (``pose-lifter
        demo`` passes those of ``pose-lifter lift BAG``).
    out : path
        Output directory (created).
    bag : path, optional
        The bag to lift: an MCAP file or a rosbag2 directory (default: the committed
        :data:`DEFAULT_DEMO_BAG`).
    workers : int
        Processes lifting the tracks (results identical to 1).

    Returns
    -------
    int
        The exit code (0).
    """
    from pose_lifter.messages import convert as m
    from pose_lifter.messages.names import TOPIC_GROUND_TRUTH
    from pose_lifter.offline.bags import bag_path, read_messages
    from pose_lifter.offline.evaluate import evaluate_bag, format_evaluation
    from pose_lifter.offline.lift import lift_bag

    bag = bag_path(bag) if bag else find_demo_bag()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    lifter = make_lifter()
    summary, lifted = lift_bag(bag, out / "demo.mcap", lifter, settings, overwrite=True, workers=workers)
    print(f"lifted {summary.n_lifted} skeletons of {bag.name} ({summary.n_warm} warm-started), "
          f"{summary.mean_solve_time_ms:.1f} ms per skeleton")
    ev = evaluate_bag(out / "demo.mcap", lifter.bases)
    print(format_evaluation(ev))
    truth = {}
    for x in read_messages(bag, [TOPIC_GROUND_TRUTH]):
        s = m.stamp_to_ns(x.msg.header.stamp)
        for sk in x.msg.skeletons:
            truth[(s, int(sk.track_id))] = m.skeleton3d_to_joints(sk)
    stamps = sorted({f.stamp_ns for f in lifted})
    picks = [stamps[i] for i in np.linspace(0, len(stamps) - 1, 3).round().astype(int)] if stamps else []
    frames = [{"stamp_ns": s, "people": [
        {"track_id": f.track_id, "points_2d": f.points_2d, "confidence": f.confidence,
         "lifted": f.joints_m, "truth": truth.get((s, f.track_id))}
        for f in lifted if f.stamp_ns == s]} for s in picks]
    table = ev.table()["lifter"]
    plot_frames(frames, out / "demo.png",
                title=f"{bag.name}: P-MPJPE {table['p_mpjpe_mm'] or float('nan'):.0f} mm, "
                      f"MPJPE {table['mpjpe_mm'] or float('nan'):.0f} mm")
    print(f"wrote {out / 'demo.mcap'} (open in Foxglove / RViz: /skeleton_markers) and {out / 'demo.png'}")
    return 0
