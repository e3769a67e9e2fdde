"""dualfem: dual methods and trusted QP solvers for elastic bodies with a thin defect.

The public API: :class:`~dualfem.qp.QP`, :class:`~dualfem.solution.Solution`,
:class:`~dualfem.solution.Status`, :mod:`~dualfem.evaluator`, :func:`~dualfem.runner.run`,
:func:`~dualfem.scene.load_scene`, :class:`~dualfem.workspace.Workspace` (one scene's assembly and
factorization reused across deltas, loads and solvers: setup / update / solve), and the plugin bases
:class:`~dualfem.solver.Solver` and :class:`~dualfem.problem.Problem`.
"""
from dualfem.core.errors import InputError, MissingDependency
from dualfem.core.qp import QP
from dualfem.core.solution import Solution, Status

__version__ = "0.1.0"

__all__ = ["QP", "Solution", "Status", "InputError", "MissingDependency", "__version__"]
