"""An explicit workspace: what one scene reuses across solves, owned by one object (setup / update / solve).

    from dualfem.workspace import Workspace
    ws = Workspace("f2", {"N": 256})
    for delta in (1e-1, 1e-5, 1e-9):
        sol = ws.update(delta=delta).solve("pdas")
        print(delta, sol.status, sol.iterations)

Who owns what is reused (nothing is kept by a module):

* the delta-free assembly (mesh, DOF maps, elastic stiffness K_el, the planned interface sum, F of
  the last load): the workspace's problem instance (its ``shared``, a :class:`dualfem.core.problem.Shared`),
  handed on by :meth:`~dualfem.core.problem.Problem.with_params` to the instance of each update;
* the linear-algebra context (backend, dual-operator kind, threads, memory budget: ``la``, a
  :class:`~dualfem.numerics.la.LinearAlgebra`), active while it sets up, solves and certifies;
* the factorization of K_fixed with its Schur complement onto the defect unknowns: the workspace's
  :class:`~dualfem.numerics.linalg.FactorStore`, which every QP it builds names (``QP.store``), so
  every delta, load, solver and certificate of the workspace works on one factorization.

Lifecycle: :meth:`Workspace.setup` assembles and factorizes (called by the first use if not
before); :meth:`Workspace.update` makes the QP for new values of the keys the problem declares in
``update_keys`` (thin_defect and three_d: ``delta``, ``load``, ``load_scale``, ``boundary``, ``body_force``,
``remote_stress``), reusing both (new supports in ``boundary`` re-assemble K_fixed on the same mesh: one more
assembly and factorization); any other key (``N``, ``E``, a defect, ...) changes the mesh and is refused
(make a new Workspace);
:meth:`Workspace.solve` runs a solver on the current QP (:func:`dualfem.experiments.runner.run`:
timed, residuals, certified); :meth:`Workspace.clear` drops the factorizations, so the next solve
pays for one again (cold timings; the assembly is kept). Counters: ``assemblies``,
``factorizations``, ``builds``.
"""
from __future__ import annotations

from typing import Any

from dualfem.core.errors import InputError
from dualfem.core.problem import Problem
from dualfem.core.qp import QP
from dualfem.core.solution import Solution
from dualfem.core.solver import Solver
from dualfem.numerics.la import LinearAlgebra


class Workspace:
    """One scene's reusable data with a setup / update / solve lifecycle (see the module docstring).

    ``scene``: a built-in scene name, a ``.toml`` scene file, a ``.npz``/``.mat`` QP file
    (:func:`dualfem.core.scene.load_scene`, with ``params`` as overrides) or a problem instance.
    ``la``: the linear-algebra context (:class:`dualfem.numerics.la.LinearAlgebra`: backend, operator kind,
    threads, memory budget; default: the process's current one, taken now), active while the workspace sets
    up, solves and certifies; ``factor``: its backend instead (solvers with a ``factor`` parameter are given
    it unless their params name one).
    """

    def __init__(self, scene: str | Problem, params: dict[str, Any] | None = None, *, factor: str | None = None,
                 la: LinearAlgebra | None = None):
        from dualfem.core.scene import load_scene
        from dualfem.numerics.la import current
        from dualfem.numerics.linalg import FactorStore

        if isinstance(scene, Problem):
            if params:
                scene = scene.with_params(**params)
            self.problem = scene
        else:
            self.problem = load_scene(scene, params)          # validated now; nothing assembled yet
        #: the linear-algebra context of every setup, solve and certificate of this workspace
        self.la = (current() if la is None else la).with_(factor=factor)  # unknown/missing backend: InputError
        self.factor = factor
        self.store = FactorStore()
        self.builds = 0
        self._qp: QP | None = None

    # ------------------------------------------------------------------ lifecycle
    def setup(self, *, factorize: bool = True) -> Workspace:
        """Assemble the QP of the current parameters and (``factorize``) factorize its K_fixed now."""
        from dualfem.numerics.linalg import factor_fixed, too_many_local

        qp = self._build(self.problem)
        if factorize and too_many_local(qp) is None:
            factor_fixed(qp, self.la.factor)
        return self

    def update(self, delta: float | None = None, load: Any = None, **keys: Any) -> Workspace:
        """The QP for new values of the problem's ``update_keys`` (delta, load, ...), reusing the assembly and
        the factorization; returns the workspace (``ws.update(delta=1e-9).solve("pdas")``).

        A key that would change the mesh or the delta-free stiffness K_fixed is refused (InputError):
        make a new Workspace for it.
        """
        changes = {**({} if delta is None else {"delta": delta}), **({} if load is None else {"load": load}), **keys}
        p = self.problem
        allowed = tuple(getattr(p, "update_keys", ()))
        for k in changes:
            if k not in p.defaults:
                raise InputError(f"unknown scene key {k!r} for problem {p.name!r}; "
                                 f"update() changes only {', '.join(allowed) or 'nothing'}")
            if k not in allowed:
                raise InputError(f"update() cannot change {k!r}: it changes the mesh or the delta-free stiffness "
                                 f"K_fixed of problem {p.name!r}, which this workspace assembled and factorized once; "
                                 f"update() changes only {', '.join(allowed) or 'nothing'}: make a new Workspace "
                                 f"for another {k}")
        new = p.with_params(**changes) if changes else p
        self._build(new)
        self.problem = new                  # only once the new parameters gave a QP
        return self

    def solve(self, solver: Solver | str, params: dict[str, Any] | None = None, *,
              tol: float | None = None) -> Solution:
        """Run ``solver`` (an instance, or a registry name plus ``params``) on the current QP:
        :func:`dualfem.experiments.runner.run` (setup and solve timed, residuals, certified)."""
        from dualfem.core.registry import get_solver
        from dualfem.experiments.runner import run

        params = dict(params or {})
        if isinstance(solver, str) and self.factor is not None and "factor" not in params \
                and "factor" in get_solver(solver).defaults:
            params["factor"] = self.factor
        with self.la.active():             # the solver and the certificate take it from the context
            return run(solver, self.qp, params, tol=tol)

    def clear(self) -> Workspace:
        """Drop the factorizations (the next solve factorizes again: cold timings); the assembly is kept."""
        self.store.clear()
        return self

    # ------------------------------------------------------------------- state
    @property
    def qp(self) -> QP:
        """The current QP (set up first if nothing was built yet)."""
        if self._qp is None:
            self.setup()
        assert self._qp is not None
        return self._qp

    @property
    def assemblies(self) -> int:
        """Delta-free assemblies the problem made for this workspace (0 for a problem that keeps none)."""
        shared = getattr(self.problem, "shared", None)
        return int(shared.assemblies) if shared is not None else 0

    @property
    def factorizations(self) -> int:
        """Factorizations of K_fixed made for this workspace (``clear`` does not reset it)."""
        return int(self.store.factorizations)

    def __repr__(self) -> str:
        return (f"Workspace({self.problem.name!r}, builds={self.builds}, assemblies={self.assemblies}, "
                f"factorizations={self.factorizations})")

    def _build(self, problem: Problem) -> QP:
        qp = problem.build()
        qp.store = self.store
        self._qp = qp
        self.builds += 1
        return qp
