"""A bag's first pass: the keypoint messages, the camera infos and the depth images' header stamps.

:func:`pose_lifter.offline.lift.lift_bag` reads what it lifts in one stream before the lift
(:func:`read_first_pass`). Where the bag has a depth topic that pass decompresses the images'
chunks to read their headers (a 640x480 recording: ~0.3 ms a frame), work that needs no lifter:
:func:`read_ahead` then reads it in a forked process while the caller builds the lifter (loading
its compiled kernels, ~0.35 s), and hands it over when asked (its pickle: ~0.1 ms a frame). Without
a depth topic the pass is short (~10 us a message) and is read when asked, in this process.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pose_lifter.core.errors import InvalidInputError
from pose_lifter.messages import cdr
from pose_lifter.messages import convert as m
from pose_lifter.messages.names import SKELETON2D_ARRAY
from pose_lifter.offline.bags import read_messages
from pose_lifter.offline.depth import HEADER_BYTES, DepthStamp, depth_topic_of, header_stamp
from pose_lifter.offline.settings import LiftSettings

__all__ = ["FirstPass", "FirstPassAhead", "FirstPassPlan", "read_ahead", "read_first_pass"]


@dataclass
class FirstPass:
    """What :func:`read_first_pass` reads."""

    keypoints: list[tuple[int, Any]]  #: (bag stamp, Skeleton2DArray) per keypoint message
    infos: list[tuple[int, Any]]  #: (bag stamp, CameraInfo)
    depth_stamps: list[tuple[int, int]] | None  #: per depth message (bag stamp, header stamp)


@dataclass(frozen=True)
class FirstPassPlan:
    """What the first pass of :func:`~pose_lifter.offline.lift.lift_bag` reads of a bag of
    ``topics`` (topic -> type) with ``settings``.

    Attributes
    ----------
    topic : str
        The keypoints.
    info_topic : str or None
        The camera infos (None: the bag has none).
    max_messages : int or None
        Keypoint messages read at most (None: all).
    depth : (topic, type) or None
        The depth images whose header stamps are read (None: no depth).
    """

    topic: str
    info_topic: str | None
    max_messages: int | None
    depth: tuple[str, str] | None

    @classmethod
    def of(cls, in_path: str | Path, settings: LiftSettings, topics: dict[str, str]) -> FirstPassPlan:
        depth_topic = depth_topic_of(topics, settings.frame.depth_topic, in_path)
        info = settings.camera_info_topic
        cap = None if settings.max_messages is None else settings.max_messages * settings.every
        return cls(settings.topic, info if info in topics else None, cap,
                   None if depth_topic is None else (depth_topic, topics[depth_topic]))


def read_first_pass(in_path: str | Path, plan: FirstPassPlan) -> FirstPass:
    """A bag's keypoint messages ``(stamp, Skeleton2DArray)`` of ``plan.topic`` (the first
    ``plan.max_messages``; YOLO detections converted, their ids made track ids), its camera infos
    ``(stamp, CameraInfo)`` of ``plan.info_topic`` and, of the ``plan.depth`` topic, each message's
    (bag stamp, header stamp) in read order (:func:`~pose_lifter.offline.depth.header_stamp`: the
    images are not kept), read in one stream (to the bag's end for the depth stamps when
    ``max_messages`` cuts the keypoints).

    Raises
    ------
    InvalidInputError
        The bag has no message of ``plan.topic``.
    """
    from pose_lifter.messages.adapters import TrackIds

    topic, depth, max_messages = plan.topic, plan.depth, plan.max_messages
    types = m.rosbags_types()
    ids = TrackIds()
    wanted = [topic] + ([plan.info_topic] if plan.info_topic is not None else [])
    decoders: dict[str, Callable[[bytes], Any]] = {SKELETON2D_ARRAY: cdr.decode_skeleton2d_array}
    if depth is not None:
        wanted.append(depth[0])
        decoders[depth[1]] = header_stamp
    out = FirstPass([], [], [] if depth is not None else None)
    full = False
    heads = {depth[1]: HEADER_BYTES} if depth is not None else None
    for x in read_messages(in_path, wanted, decoders=decoders, heads=heads):
        if depth is not None and x.topic == depth[0]:
            stamp = x.msg if isinstance(x.msg, DepthStamp) else DepthStamp(m.stamp_to_ns(x.msg.header.stamp))
            assert out.depth_stamps is not None
            out.depth_stamps.append((x.stamp_ns, stamp.stamp_ns))
        elif x.topic == topic:
            full = full or (max_messages is not None and len(out.keypoints) >= max_messages)
            if full and depth is None:
                break
            if not full:
                out.keypoints.append((x.stamp_ns, _as_skeleton2d(x.msg, x.msgtype, types, ids)))
        elif not full:
            out.infos.append((x.stamp_ns, x.msg))
    if not out.keypoints:
        raise InvalidInputError(f"{in_path} has no {topic} messages")
    return out


def _as_skeleton2d(msg: Any, msgtype: str, types: Any, track_ids: Any) -> Any:
    """A Skeleton2DArray from a liftable message (yolo DetectionArray -> wang12 array)."""
    if msgtype == SKELETON2D_ARRAY:
        return msg
    from pose_lifter.messages import adapters

    people, _ = adapters.yolo_detections_to_people(msg, track_ids)
    return adapters.people_to_skeleton2d_array(msg.header, people, types)


class FirstPassAhead:
    """A bag's first pass, read ahead (:func:`read_ahead`): called (once) it gives the pass, or
    raises what the pass raised; closed (a context manager) before that, it stops the reading
    process, so that a caller that fails on the way (a bad basis file) ends at once."""

    def __init__(self, in_path: str | Path, plan: FirstPassPlan) -> None:
        self.in_path, self.plan = in_path, plan
        self._ex: Any = None
        self._future: Any = None
        if plan.depth is not None:
            import multiprocessing
            from concurrent.futures import ProcessPoolExecutor

            from pose_lifter.offline.workers import quiet_worker

            self._ex = ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("fork"),
                                           initializer=quiet_worker, initargs=(os.getpid(),))
            self._future = self._ex.submit(read_first_pass, in_path, plan)

    def __call__(self) -> FirstPass:
        if self._future is None:
            return read_first_pass(self.in_path, self.plan)
        try:
            out: FirstPass = self._future.result()
        except BaseException:  # what the pass raised, or Ctrl-C: the process stopped now
            self.close()
            raise
        self._ex.shutdown()
        self._ex = None
        return out

    def close(self) -> None:
        """Stop the reading process if it still runs (nothing when the pass was given)."""
        if self._ex is not None:
            from pose_lifter.offline.workers import stop_workers

            stop_workers(self._ex)
            self._ex = None

    def __enter__(self) -> FirstPassAhead:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def read_ahead(in_path: str | Path, plan: FirstPassPlan) -> FirstPassAhead:
    """The first pass of a bag, to be asked for: with a depth topic read now in a forked process,
    beside the caller's own work (the module docstring); without, read when asked."""
    return FirstPassAhead(in_path, plan)
