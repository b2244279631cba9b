"""A bag's depth images for an offline lift: which topic, each keypoints message's partner on it,
and the partners read one at a time while the chains are lifted.

* :func:`depth_topic_of`: the topic ``--depth-topic`` names (a topic the bag lacks, or of another
  type, is an error naming the bag's image topics), or, when it names none (``""``), the bag's
  one ``Image`` / ``CompressedImage`` topic whose name holds ``depth`` (none, or several: no
  depth, the monocular lift); ``none``: no depth.
* :func:`pair_depth`: each image's header stamp (:func:`header_stamp`, from the image's first
  bytes alone; read in the pass that reads the keypoints, :func:`pose_lifter.offline.lift.lift_bag`,
  or in a pass of its own), then each keypoints message paired with the image of the nearest
  stamp within ``depth_tolerance`` (the node's :class:`~pose_lifter.messages.depth.DepthBuffer`,
  holding the stamps only), by the keypoints' header stamp (the bag stamp where it is 0): a
  detector's keypoints arrive after their image by its latency, so their bag stamps are not the
  image's.
* :class:`DepthFrames`: the partners read while the chains are lifted, one image decoded at a
  time (:func:`~pose_lifter.messages.depth.read_depth`, a 16-bit image kept in millimetres: a
  view of the chunk's bytes, which it keeps while it is held; checked against the ``camera_info``
  size at the message), so memory is bounded by the images of one step of the lift (at most
  :data:`HELD_IMAGES`, and the chunks that hold them) whatever the bag's length; in a single
  chunked MCAP file each image is read from its own chunk through
  the file's index (:mod:`pose_lifter.offline.mcap_index`: no pass over the topic, so worker
  processes lifting different tracks decompress different chunks), elsewhere through the topic in
  message order. A worker process opens its own reader. A refused image (see
  :mod:`pose_lifter.messages.depth`) leaves its frame to the 2D alone.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final, NamedTuple

from pose_lifter.messages.convert import stamp_to_ns
from pose_lifter.messages.depth import (
    DepthBuffer,
    DepthError,
    check_depth_size,
    decode_compressed_image_cdr,
    decode_header_cdr,
    decode_image_cdr,
    read_depth,
)
from pose_lifter.messages.names import COMPRESSED_IMAGE, IMAGE
from pose_lifter.offline.bags import BagError, RawMessage, read_raw
from pose_lifter.offline.mcap_index import ChunkedMcap, IndexedMessages, chunked_mcap

if TYPE_CHECKING:
    from pose_lifter.core.depth.reading import DepthArray

__all__ = ["HEADER_BYTES", "HELD_IMAGES", "IMAGE_TYPES", "NO_DEPTH", "BagDepth", "DepthFrames", "DepthStamp",
           "depth_topic_of", "header_stamp", "pair_depth"]

#: The message types of a depth topic.
IMAGE_TYPES: Final[tuple[str, ...]] = (IMAGE, COMPRESSED_IMAGE)
#: ``--depth-topic`` value that turns the depth off offline.
NO_DEPTH: Final[str] = "none"


def depth_topic_of(topics: dict[str, str], named: str, bag: str | Path) -> str | None:
    """The depth topic of a bag of ``topics`` (topic -> type) for ``--depth-topic named`` (see the
    module doc); None: no depth.

    Raises
    ------
    BagError
        ``named`` is not a topic of the bag, or not an ``Image`` / ``CompressedImage`` one.
    """
    images = sorted(t for t, kind in topics.items() if kind in IMAGE_TYPES)
    if named == NO_DEPTH:
        return None
    if not named:
        found = [t for t in images if "depth" in t.lower()]
        return found[0] if len(found) == 1 else None
    if named not in topics:
        raise BagError(f"{bag} has no depth topic {named!r}; its image topics: {images or 'none'}")
    if topics[named] not in IMAGE_TYPES:
        raise BagError(f"depth topic {named!r} of {bag} is {topics[named]}, not {' or '.join(IMAGE_TYPES)}; "
                       f"its image topics: {images or 'none'}")
    return named


def _decoder(msgtype: str) -> Any:
    return decode_compressed_image_cdr if msgtype == COMPRESSED_IMAGE else decode_image_cdr


@dataclass(frozen=True)
class BagDepth:
    """A bag's depth topic and each keypoints message's partner on it.

    Attributes
    ----------
    path : Path
    topic, msgtype : str
    partners : tuple of (int or None)
        Per keypoints message (in the order given to :func:`pair_depth`): the index of its
        partner among the topic's messages, or None.
    sizes : tuple of ((float, float) or None)
        Per keypoints message: the (width, height) of the camera_info at it (None: none or no size).
    paired : int
    unpaired : Counter of str
        Messages without a partner, by why (:class:`~pose_lifter.messages.depth.PairFault`).
    located : (ChunkedMcap, positions) or None
        The topic's messages in the chunks of a single MCAP file (each its log time, chunk and
        offset, :meth:`~pose_lifter.offline.mcap_index.ChunkedMcap.positions`), read by number; None:
        read as a stream.
    """

    path: Path
    topic: str
    msgtype: str
    partners: tuple[int | None, ...]
    sizes: tuple[tuple[float, float] | None, ...]
    paired: int = 0
    unpaired: Counter[str] = field(default_factory=Counter)
    located: tuple[ChunkedMcap, tuple[tuple[int, int, int], ...]] | None = None

    def frames(self) -> DepthFrames:
        """A reader of the partners (open it in the process that reads)."""
        return DepthFrames(self)

    def first_refusal(self) -> str:
        """Why the first paired image is refused (read and checked here: a topic whose images are
        all unusable, e.g. of another encoding or size, said once before the lift); ``""``: it is
        usable, or nothing is paired."""
        first = next((i for i, k in enumerate(self.partners) if k is not None), None)
        if first is None:
            return ""
        with self.frames() as frames:
            frames.image(first)
        return next(iter(frames.reasons.values()), "")


#: The most depth images (and, read by number, the most chunks holding them) held at once while the
#: chains are lifted: one per message of a step (:func:`pose_lifter.offline.chains.lift_chains`).
HELD_IMAGES: Final[int] = 16
#: The bytes of a depth message that hold its header (for any frame id of a sane length).
HEADER_BYTES: Final[int] = 1024


def header_stamp(data: Any) -> DepthStamp:
    """A depth message's header stamp, read from its first bytes alone (at most
    :data:`HEADER_BYTES` are needed; a decoder for :func:`~pose_lifter.offline.bags.read_messages`);
    -1 when they do not even hold a header."""
    try:
        return DepthStamp(stamp_to_ns(decode_header_cdr(data).stamp))
    except DepthError:
        return DepthStamp(-1)


class DepthStamp(NamedTuple):
    """A depth message's header stamp (ns; -1: no header), as :func:`header_stamp` reads it."""

    stamp_ns: int


def pair_depth(path: str | Path, topic: str, msgtype: str, frame_stamps: Sequence[int],
               sizes: Sequence[tuple[float, float] | None], tolerance_s: float,
               stamps: Sequence[tuple[int, int]] | None = None) -> BagDepth:
    """Each keypoints message (its stamp in ``frame_stamps``: the header's, or the bag's where that
    is 0) paired with the depth image of ``topic`` of the nearest header stamp within
    ``tolerance_s`` (the stamps held, never the images).

    ``stamps``: each depth message's (bag stamp, header stamp, -1 for none) in read order, as the
    caller read them (:func:`header_stamp`, in the pass that reads the keypoints); None: read here,
    one pass over the topic reading the headers only. A single chunked MCAP file's depth messages
    are then located in its chunks (:meth:`~pose_lifter.offline.mcap_index.ChunkedMcap.positions`),
    so that :class:`DepthFrames` reads each partner's chunk alone."""
    if stamps is None:
        stamps = [(raw.stamp_ns, header_stamp(raw.data).stamp_ns) for raw in read_raw(path, [topic])]
    buffer: DepthBuffer[int] = DepthBuffer(max(1, len(stamps)), round(tolerance_s * 1e9))
    for k, (_, s) in enumerate(stamps):
        if s >= 0:  # not even a header: never a partner
            buffer.push(s, k)
    partners = tuple(buffer.pair(s).image for s in frame_stamps)
    mcap = chunked_mcap(path)
    positions = None if mcap is None else mcap.positions(mcap.channel_ids([topic]))
    if positions is not None and [t for t, _, _ in positions] != [t for t, _ in stamps]:
        positions = None  # not the messages the stream gave: read them as a stream
    return BagDepth(Path(path), topic, msgtype, partners, tuple(sizes), buffer.paired,
                    Counter({str(k): v for k, v in buffer.unpaired.items()}),
                    None if mcap is None or positions is None else (mcap, tuple(positions)))


class DepthFrames:
    """The depth images of a :class:`BagDepth`'s keypoints messages. Located in a chunked MCAP
    file, each is read from its chunk (:class:`~pose_lifter.offline.mcap_index.IndexedMessages`: one
    chunk decompressed at a time, in any order); otherwise read forward through the topic one
    message at a time (asked out of order, it reads the topic again from its start). A context
    manager; :attr:`refused` counts the images refused by kind, :attr:`reasons` the first reason of
    each kind, :attr:`n_passes` the streams opened over the topic (0 when located)."""

    def __init__(self, depth: BagDepth) -> None:
        self.depth = depth
        self.refused: Counter[str] = Counter()
        self.reasons: dict[str, str] = {}
        self.n_passes = 0
        self._stream: Iterator[RawMessage] | None = None
        self._next = 0  # index of the topic's message the stream gives next
        self._last: tuple[int, DepthArray | None] | None = None  # (index, its image)
        self._indexed = (IndexedMessages(*depth.located, keep=HELD_IMAGES) if depth.located is not None
                         else None)

    def __enter__(self) -> DepthFrames:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        stream, self._stream = self._stream, None
        close = getattr(stream, "close", None)  # read_raw's generator: closing it closes the bag
        if close is not None:
            close()
        if self._indexed is not None:
            self._indexed.close()

    def _data(self, index: int) -> Any:
        if self._indexed is not None:
            return self._indexed.data(index)
        if self._stream is None or index < self._next:
            self.close()
            self._stream, self._next = read_raw(self.depth.path, [self.depth.topic]), 0
            self.n_passes += 1
        stream = self._stream
        for raw in stream:
            self._next += 1
            if self._next - 1 == index:
                return raw.data
        raise BagError(f"{self.depth.path}: depth topic {self.depth.topic} has no message {index}")

    def image(self, msg_index: int) -> DepthArray | None:
        """The depth image of keypoints message ``msg_index`` (a 16-bit one as uint16 millimetres:
        :func:`~pose_lifter.messages.depth.read_depth` with ``millimetres``), or None (no partner,
        or refused: counted in :attr:`refused`)."""
        index = self.depth.partners[msg_index]
        if index is None:
            return None
        if self._last is None or self._last[0] != index:
            self._last = (index, None)
            try:
                self._last = (index, read_depth(_decoder(self.depth.msgtype)(self._data(index)),
                                                millimetres=True))
            except DepthError as err:
                self._refuse(err)
                return None
        image, size = self._last[1], self.depth.sizes[msg_index]
        if image is None:  # refused already (counted once)
            return None
        try:
            return check_depth_size(image, size) if size is not None else image
        except DepthError as err:
            self._refuse(err)
            return None

    def _refuse(self, err: DepthError) -> None:
        self.refused[str(err.fault)] += 1
        self.reasons.setdefault(str(err.fault), str(err))
