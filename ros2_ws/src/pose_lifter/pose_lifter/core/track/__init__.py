"""A person over frames: the per-track policy that lifts each frame warm (``policy``; its records,
``records``), the screening of a frame's people (``screening``), a track's state (``state``) and
default settings (``defaults``), the causal smoothing (``smoothing``) and measurement update
(``measurement``) of the published pose, and its metric placement in the camera frame
(``placement``).
"""
