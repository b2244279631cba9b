"""One frame of one person: the input checks and the modes (``lifter``: paper, hybrid, learned),
the hybrid fit with the learned prior (``hybrid``), the starts of each mode (``starts``), the
alternation runs (``runs``), and the rounds that hand a frame's runs and prior poses to one
compiled pass each (``batch``).
"""
