"""Methods the paper compares against, behind the lifter's call shape (``lift``, ``lift_many``).

* :mod:`.ramakrishna`: Ramakrishna, Kanade & Sheikh (ECCV 2012), projected matching pursuit
  over class-wise PCA bases (``from pose_lifter.core.baselines.ramakrishna import
  RamakrishnaLifter``).
"""
