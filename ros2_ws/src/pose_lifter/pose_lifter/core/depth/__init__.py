"""Depth fused with the lift: a registered depth image places each person in metres, corrects the
joints it sees and leaves the lifted shape to the joints it does not; every joint gets a standard
deviation (:mod:`.fuse`, :mod:`.reading`, :mod:`.uncertainty`). Pure numpy; the node and the offline
lift hand it the depth image of a frame (:mod:`pose_lifter.messages.depth` decodes ROS images)."""

from __future__ import annotations

from pose_lifter.core.depth.fuse import (
    DepthReadings,
    FusedPeople,
    fuse_depth,
    fuse_readings,
    read_and_fuse,
    read_depth,
)
from pose_lifter.core.depth.reading import SURFACE_OFFSET_M, DepthArray, DepthOptions, read_patches
from pose_lifter.core.depth.uncertainty import body_std, monocular_std

__all__ = ["SURFACE_OFFSET_M", "DepthArray", "DepthOptions", "DepthReadings", "FusedPeople", "body_std",
           "fuse_depth", "fuse_readings", "monocular_std", "read_and_fuse", "read_depth", "read_patches"]
