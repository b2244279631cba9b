"""The alpha-step solvers of the pose ADM (paper appendix A): each minimises the limb-constrained
least squares ``min ||A alpha - d1||^2 + ||alpha - d2||^2`` s.t. ``||C_i y||^2 = L_i``.

* :mod:`.lifted_admm`: the paper's rank-1 lifting solved by the inner (Q, P) ADM;
* :mod:`.sphere_newton`: Riemannian Newton on the product of the 8 limb spheres (on bases whose
  limb map is onto: every shipped set).
"""
