"""A frame's answer, once: its outgoing messages from its lifted skeletons.

The node publishes what :func:`frame_answer` gives and the offline lift writes it
(:func:`pose_lifter.offline.lift.lift_bag`), so a lifted bag holds what the node published:

* ``skeletons_3d`` (``Skeleton3DArray``, :func:`~pose_lifter.messages.cdr.skeleton3d_array_cdr`),
* ``skeleton_markers`` (``MarkerArray``, :func:`~pose_lifter.messages.cdr.marker_array_cdr`, what is
  gone from :class:`~pose_lifter.messages.markers.MarkerBook`),
* the REP-155 bodies and their ``/tf`` (:class:`~pose_lifter.messages.hri.BodyBook`).

The books carry what is on screen and which bodies are alive from one frame to the next; the
caller owns them (one per output stream). All CDR bytes, no rclpy, no I/O.

A live stream's frames take one way (:class:`AnswerStream`, the node's): the serialised frame is
read (:func:`~pose_lifter.messages.cdr.read_skeleton2d_array`), checked and lifted
(:class:`~pose_lifter.messages.frame.FramePipeline`; with a lag, held and refined over the next
frames, :class:`~pose_lifter.messages.lagged.LaggedFrames`) and answered (:func:`frame_answer`).
What it gives back is data (:class:`FrameStep`): the answers to publish and what was refused or
clipped on the way, which the caller counts and logs.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

from pose_lifter.messages import cdr
from pose_lifter.messages.body import BodyPose
from pose_lifter.messages.cdr import DecodedHeader, SkeletonFrame, read_skeleton2d_array
from pose_lifter.messages.convert import stamp_to_ns
from pose_lifter.messages.frame import DepthImage, FramePipeline, Intrinsics, LiftedSkeleton, SkipSkeleton
from pose_lifter.messages.hri import BodyBook, BodyFrame, LaterBodies
from pose_lifter.messages.lagged import LaggedFrame, LaggedFrames
from pose_lifter.messages.markers import MarkerBook
from pose_lifter.messages.names import MARKER_ARRAY, SKELETON3D_ARRAY, TOPIC_MARKERS, TOPIC_SKELETONS

__all__ = ["AnswerStream", "AnsweredFrame", "FrameAnswer", "FrameStep", "frame_answer"]


@dataclass(frozen=True)
class FrameAnswer:
    """The serialised answer of one frame.

    Attributes
    ----------
    skeletons : bytes
        ``Skeleton3DArray`` with the input's header.
    markers : bytes or None
        ``MarkerArray`` (None: no markers book).
    later_bodies : LaterBodies or None
        The REP-155 messages (None: no bodies book), computed when :attr:`bodies` is first read
        and at the latest before the book's next frame.
    """

    skeletons: bytes
    markers: bytes | None = None
    later_bodies: LaterBodies | None = None  #: the bodies, computed when first read

    @property
    def bodies(self) -> BodyFrame | None:
        """The REP-155 messages (None: no bodies book), computed when first read, so that a
        publisher sends the skeletons first."""
        return self.later_bodies() if self.later_bodies is not None else None

    def messages(self) -> list[tuple[str, bytes, str]]:
        """Everything, in the node's publishing order, as (default topic, CDR, type)."""
        out = [(TOPIC_SKELETONS, self.skeletons, SKELETON3D_ARRAY)]
        if self.markers is not None:
            out.append((TOPIC_MARKERS, self.markers, MARKER_ARRAY))
        return out + (self.bodies.messages() if self.bodies is not None else [])


def frame_answer(header: Any, stamp_ns: int, lifted: SkeletonFrame, *, markers: MarkerBook | None = None,
                 marker_lifetime: float = 0.0, bodies: BodyBook | None = None,
                 image_size: tuple[float, float] | None = None,
                 body_poses: Sequence[BodyPose | None] | None = None) -> FrameAnswer:
    """The answer of one frame: its lifted skeletons (in message order) as ``Skeleton3DArray``,
    the markers that show them (``markers``' book updated) and their REP-155 bodies (``bodies``'
    book updated).

    The books say what changes (markers gone, bodies new and gone); the header is written once
    (its CDR, and the bodies' with their clock) and each message is written after it.

    Parameters
    ----------
    header : the answer's ``std_msgs/Header`` (``stamp.sec``, ``stamp.nanosec``, ``frame_id``)
    stamp_ns : int
        The frame's stamp (the bodies' clock: the header's, or the arrival time when it is 0).
    lifted : SkeletonFrame
        Its ``std_m`` rows are the skeletons' ``joint_std`` (empty where unknown:
        :attr:`~pose_lifter.messages.frame.LiftedSkeleton.std_m` None).
    markers, bodies : the stream's books, or None (that output off)
    marker_lifetime : float
        Seconds (0: until replaced or deleted).
    image_size : (width, height) in pixels, or None (no REP-155 ``skeleton2d`` / ``roi``)
    body_poses : the bodies' poses of the tracked rows, computed ahead, or None
        (:meth:`~pose_lifter.messages.hri.BodyBook.frame`)
    """
    head = cdr.message_header(header)
    skeletons = cdr.skeleton3d_array_cdr(head, lifted)
    shown = None
    if markers is not None:
        track_ids = lifted.track_ids.tolist()
        gone = markers.update(track_ids)
        shown = cdr.marker_array_cdr(head, track_ids, lifted.joints_m, markers.ns, marker_lifetime,
                                     **gone._asdict())
    if bodies is None:
        return FrameAnswer(skeletons, shown)
    clock = cdr.header_cdr(cdr.stamp_cdr(stamp_ns), str(header.frame_id))
    return FrameAnswer(skeletons, shown, bodies.later(stamp_ns, clock, lifted, image_size, body_poses))


@dataclass(frozen=True)
class AnsweredFrame:
    """One input frame's answer, ready to publish.

    Attributes
    ----------
    answer : FrameAnswer
    lifted : list of LiftedSkeleton
        Its lifted skeletons, in message order (what the answer carries).
    received : float
        When its input arrived (the caller's clock; its latency counts from it).
    """

    answer: FrameAnswer
    lifted: list[LiftedSkeleton]
    received: float


@dataclass(frozen=True)
class FrameStep:
    """What one input frame (or a flush of the frames held for the lag) gave.

    Attributes
    ----------
    answers : tuple of AnsweredFrame
        In input order: this frame's answer at once (no lag), those the lag releases, or none
        (a frame over a cap is left unanswered).
    skipped : tuple of (str, str)
        What was refused, as (kind, reason): the frame itself (over a cap, unknown layout, too
        many skeletons), then, per answer, its skeletons left out (bad input or a failed solve;
        ``"skeleton skipped: "`` before the reason), in message order.
    clipped : tuple of str
        One warning per skeleton whose confidences were clipped into [0, 1].
    """

    answers: tuple[AnsweredFrame, ...] = ()
    skipped: tuple[tuple[str, str], ...] = ()
    clipped: tuple[str, ...] = ()


class _Lifted(NamedTuple):
    """A frame lifted, to answer: its header, arrival, stamp and per checked skeleton what lifting it gave."""

    header: Any
    received: float
    stamp_ns: int
    outcomes: list[LiftedSkeleton | SkipSkeleton]


def _released(frames: list[LaggedFrame[tuple[Any, float]]]) -> list[_Lifted]:
    """The frames the lag releases (their token: the input's header and arrival)."""
    return [_Lifted(held.token[0], held.token[1], held.stamp_ns, held.outcomes) for held in frames]


class AnswerStream:
    """One input stream's frames, each from its serialised bytes to its answer.

    Parameters
    ----------
    pipeline : FramePipeline
        Checks, tracks and placement (its settings and lifter may change between frames).
    lag : int
        ``output_lag``: each answer given this many frames later, its poses refined over them
        (0: at once).
    fallback : callable
        Reads the serialised frames the array reader refuses (e.g. rclpy's deserialiser).

    Attributes
    ----------
    markers, bodies : MarkerBook or BodyBook, or None
        The stream's books (None: that output off).
    frame_id : str
        The answer's frame when the input's ``header.frame_id`` is empty.
    marker_lifetime : float
        Seconds (0: until replaced or deleted).
    intrinsics : Intrinsics
        The camera's, or None (weak perspective, the default distance).
    image_size : (width, height) in pixels, or None
    depth_of : callable or None
        ``depth_of(stamp_ns)``: the depth image of the frame of that stamp, or None (lifted from the
        2D alone); None: no depth.
    """

    def __init__(self, pipeline: FramePipeline, lag: int, fallback: Callable[[bytes], Any]) -> None:
        self.pipeline = pipeline
        self.lagged: LaggedFrames[tuple[Any, float]] | None = LaggedFrames(pipeline, lag) if lag > 0 else None
        pipeline.follow_fused(lag == 0)  # answered at once, each track's fused joints filtered
        self.fallback = fallback
        self.markers: MarkerBook | None = None
        self.bodies: BodyBook | None = None
        self.frame_id = ""
        self.marker_lifetime = 0.0
        self.intrinsics: Intrinsics = None
        self.image_size: tuple[float, float] | None = None
        self.depth_of: Callable[[int], DepthImage] | None = None

    def __len__(self) -> int:
        """The frames held for the lag."""
        return len(self.lagged) if self.lagged is not None else 0

    def answer(self, data: Any, received: float, arrival_ns: int) -> FrameStep:
        """One ``Skeleton2DArray`` (its serialised bytes, or a message object) read, checked,
        lifted and answered: its answer (or, with a lag, those it releases) and what was refused
        on the way. ``received``: when it arrived (carried to its answer); ``arrival_ns``: its
        stamp when the input's is 0 (detectors that leave it empty)."""
        msg = read_skeleton2d_array(data, self.fallback)
        clipped: list[str] = []
        checked = self.pipeline.check(msg, clipped.append)
        if not checked.answered:  # over a cap: skipped, unanswered
            return self._answered([], checked.skipped, tuple(clipped))
        header = msg.header
        if not header.frame_id:  # RViz cannot place an empty frame
            header = DecodedHeader(header.stamp, self.frame_id)
        stamp_ns = stamp_to_ns(header.stamp) or arrival_ns
        depth = self.depth_of(stamp_ns) if self.depth_of is not None and checked.skeletons else None
        if self.lagged is None:
            frames = [_Lifted(header, received, stamp_ns,
                              self.pipeline.frame(checked, stamp_ns, self.intrinsics, depth))]
        else:
            frames = _released(self.lagged.lift((header, received), stamp_ns, self.intrinsics, checked,
                                                depth))
        return self._answered(frames, checked.skipped, tuple(clipped))

    def flush(self) -> FrameStep:
        """The answers held for the lag, all of them (the input stopped: nothing later refines them)."""
        return self._answered(_released(self.lagged.flush()) if self.lagged is not None else [], (), ())

    def clear(self) -> None:
        """Forget the frames held for the lag and the tracks."""
        if self.lagged is not None:
            self.lagged.clear()
        self.pipeline.clear()

    def _answered(self, frames: list[_Lifted], skipped: tuple[SkipSkeleton, ...], clipped: tuple[str, ...]
                  ) -> FrameStep:
        """The answers of lifted frames, in order, with what was refused on the way."""
        answers: list[AnsweredFrame] = []
        refused = [(x.kind, str(x)) for x in skipped]
        for done in frames:
            lifted = [x for x in done.outcomes if not isinstance(x, SkipSkeleton)]
            refused += [(x.kind, f"skeleton skipped: {x}")
                        for x in done.outcomes if isinstance(x, SkipSkeleton)]
            answer = frame_answer(done.header, done.stamp_ns, SkeletonFrame.of(lifted), markers=self.markers,
                                  marker_lifetime=self.marker_lifetime, bodies=self.bodies,
                                  image_size=self.image_size)
            answers.append(AnsweredFrame(answer, lifted, done.received))
        return FrameStep(tuple(answers), tuple(refused), clipped)
