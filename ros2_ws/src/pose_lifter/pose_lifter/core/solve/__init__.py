"""The alternation of the paper, compiled: the camera step (``camera``), the pose step's ADM
(``pose_step`` around the compiled ``pose_kernel``) with its alpha-steps (``alpha``), and whole
runs of alternations for a batch of people in one call (``run_kernel``).
"""
