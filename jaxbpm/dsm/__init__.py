"""Direct stiffness method (DSM): the static equilibrium of the Model's forces, solved without a matrix.

Unknowns are the displacements (and, with 6 DOF per particle, the rotation vectors) of the free particles; the
clamped ones are prescribed by the scene. The residual is the Model's force function itself, so DSM and DEM differ
only by the approximations the method names: no inertia, small motion (linear DSM) and fixed contact candidates.

* **Linear** (bonds only): ``K_ff u_f = -K_fp u_p`` with ``K v`` applied bond by bond from per-bond Jacobians of the
  same bond law at rest (forward-mode derivatives, :func:`reduced_jacobians`; or a ``jax.jvp`` of the whole force
  function, ``operator="jvp"``; never an assembled matrix), solved by preconditioned CG (block-Jacobi from each
  particle's 6x6 (or 3x3) self-stiffness, plus by default a coarse space of the rigid modes of particle
  aggregates). The CG runs inside ``lax.custom_linear_solve``: derivatives with respect to the bond parameters come
  from implicit differentiation, not from unrolling the iterations; ``vmap`` over parameter sets works.
* **Nonlinear** (Hertz contacts, walls): Newton-Krylov, started from the linear bond solution; each Newton step
  solves the tangent system at the current state with GMRES (bonds and contacts element by element from their
  Jacobians there, walls by a jvp), then a backtracking line search on the residual norm. Contact candidates are the
  pairs within reach at rest (fixed in advance); a contact's tangential spring is the
  whole relative tangential displacement of its contact points since rest, capped by Coulomb (``|F_t| <= mu F_n``,
  ``slip=True``, the default) or not capped (``slip=False``: no slip, as Jarolin & Dosta 2020, 3.1.2, assumes); walls
  are ideal frictionless moving walls. Why slip by default: on contact-dominated samples most contacts slide in the
  DEM, and without slip the static solve overestimates the stiffness there.

Convergence is measured by the residual norm relative to the norm of the reaction forces. A solve that misses its
tolerance raises :class:`ConvergenceError` (``throw=True``, the default) or, with ``throw=False``, returns its
result with ``status="max_iterations"`` (``converged=False`` and ``failure`` in the stats). A sample whose free
part is not held (a cluster that touches no clamped particle and no wall) raises :class:`SceneError` naming the
particles.

The package, one module per part (each can be read and tested alone):

* :mod:`~jaxbpm.dsm.operator` -- the tangent element by element: per-bond and per-contact Jacobians, their packed
  form, the stiffness product, self-stiffness blocks, :class:`BondGeometry`;
* :mod:`~jaxbpm.dsm.preconditioner` -- block-Jacobi and the coarse space of aggregates' rigid modes;
* :mod:`~jaxbpm.dsm.krylov` -- preconditioned CG inside ``lax.custom_linear_solve`` (:func:`cg`), :func:`linear_solve`;
* :mod:`~jaxbpm.dsm.boundary` -- what a scene prescribes: free DOFs, held clusters, contact candidates;
* :mod:`~jaxbpm.dsm.linear` -- the linear scene solves (bonds only; linearised contacts), one compiled program each;
* :mod:`~jaxbpm.dsm.newton` -- the nonlinear scene solve (Newton-Krylov over load steps);
* :mod:`~jaxbpm.dsm.scene` -- :func:`solve_scene`, what ``jaxbpm.solve(..., method="dsm")`` runs;
* :mod:`~jaxbpm.dsm.functions` -- pure functions of the parameters (:func:`stiffness_function`, :func:`load_cases`);
* :mod:`~jaxbpm.dsm.failure` -- the static failure solver (:func:`failure_solve`: bonds removed one event at a time,
  sequentially linear analysis).
"""

from jaxbpm.dsm.boundary import affine_field, contact_candidates, free_mask
from jaxbpm.dsm.failure import critical_scales, failure_solve, FailureResult, StaticFailure
from jaxbpm.dsm.functions import load_cases, stiffness_function
from jaxbpm.dsm.krylov import cg, linear_solve, tangent_operator
from jaxbpm.dsm.linear import LINEAR_STIFFNESS_TOL
from jaxbpm.dsm.operator import (
    BondGeometry, block_diagonal, bond_jacobians, contact_jacobians, full_jacobians, packed_jacobians,
    reduced_jacobians, stiffness_product, symmetrised)
from jaxbpm.dsm.preconditioner import (
    CholeskyBlocks, CoarseSpace, Preconditioner, bond_geometry, build_preconditioner, coarse_space)
from jaxbpm.dsm.scene import solve_scene

__all__ = ["solve_scene", "stiffness_function", "load_cases", "linear_solve", "tangent_operator", "cg",
           "reduced_jacobians", "bond_jacobians", "full_jacobians", "packed_jacobians", "contact_jacobians",
           "symmetrised", "stiffness_product", "block_diagonal", "BondGeometry", "bond_geometry", "CoarseSpace",
           "coarse_space", "Preconditioner", "CholeskyBlocks", "build_preconditioner", "free_mask", "affine_field",
           "contact_candidates", "LINEAR_STIFFNESS_TOL", "failure_solve", "StaticFailure", "FailureResult",
           "critical_scales"]
