"""A person over frames: the per-track policy that screens each frame and lifts it warm
(``policy``), a track's state (``state``) and default settings (``defaults``), the causal smoothing
(``smoothing``) and measurement update (``measurement``) of the published pose, and its metric
placement in the camera frame (``placement``).
"""
