"""One frame of a batch of people, as stages over the batch's rows: the input checks and the modes
(``lifter``: paper, hybrid, learned), the batch's rows and the prior's pass over them (``batch``),
the hybrid fit with the learned prior (``hybrid``), the paper's starts (``starts``) and the
alternation runs, each stage's in one compiled call (``runs``).
"""
