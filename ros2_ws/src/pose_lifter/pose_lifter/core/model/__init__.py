"""What a lift knows before it sees a frame: the 12-joint skeleton and its limbs
(``skeleton``), the sparse pose bases (``bases``) and the pose-step model derived from them
(``pose_model``), the learned 2D -> 3D prior (``prior``), their loading for a lifter (``loading``),
and the errors a lift is measured by (``metrics``) on synthetic or real poses (``synthetic``).
"""
