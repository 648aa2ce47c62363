"""QP solver adapters for  min 1/2 ||c||^2  subject to  A c >= b.

Each adapter returns a :class:`QPSolution` and never raises on infeasibility:
the status is reported, and the caller verifies the point anyway (a solver's
"optimal" is not trusted on its own). Register a new solver with
:func:`register_solver`.
"""

from __future__ import annotations

import importlib.util
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ratfit.errors import InputError

__all__ = ["QPSolution", "SOLVERS", "available_solvers", "first_available", "register_solver",
           "solve_qp"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class QPSolution:
    status: str  # "optimal", "infeasible" or "error"
    x: Array | None
    message: str
    solver: str


def _quadprog(A: Array, b: Array) -> QPSolution:
    import quadprog

    k = A.shape[1]
    try:
        x = quadprog.solve_qp(np.eye(k), np.zeros(k), np.ascontiguousarray(A.T), b, 0)[0]
    except ValueError as exc:
        msg = str(exc)
        status = "infeasible" if "inconsistent" in msg else "error"
        return QPSolution(status, None, msg, "quadprog")
    return QPSolution("optimal", x, "optimal", "quadprog")


def _daqp(A: Array, b: Array, time_limit: float | None = None) -> QPSolution:
    from ctypes import c_int

    import daqp

    k, rows = A.shape[1], A.shape[0]
    kw = {} if time_limit is None else {"time_limit": float(time_limit)}
    x, _, flag, _ = daqp.solve(
        np.eye(k), np.zeros(k), np.ascontiguousarray(A), np.full(rows, 1e30), b,
        np.zeros(rows, dtype=c_int), **kw,
    )
    if flag >= 1:
        return QPSolution("optimal", np.asarray(x), f"exitflag {flag}", "daqp")
    status = "infeasible" if flag == -1 else "error"
    return QPSolution(status, None, f"exitflag {flag}", "daqp")


def _clarabel(A: Array, b: Array) -> QPSolution:
    import clarabel
    import scipy.sparse as sp

    k = A.shape[1]
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    solver = clarabel.DefaultSolver(
        sp.csc_matrix(np.eye(k)), np.zeros(k), sp.csc_matrix(-A), -b,
        [clarabel.NonnegativeConeT(A.shape[0])], settings,
    )
    res = solver.solve()
    status = str(res.status)
    if status in ("Solved", "AlmostSolved"):
        return QPSolution("optimal", np.array(res.x), status, "clarabel")
    kind = "infeasible" if "Infeasible" in status else "error"
    return QPSolution(kind, None, status, "clarabel")


# (description, solve(A, b[, time_limit=...]) -> QPSolution) per name
SOLVERS: dict[str, tuple[str, Callable[..., QPSolution]]] = {
    "quadprog": ("quadprog", _quadprog),
    "daqp": ("daqp", _daqp),
    "clarabel": ("clarabel", _clarabel),
}


# Adapters that take a ``time_limit`` keyword.
TIMED_SOLVERS = frozenset({"daqp"})


def register_solver(name: str, module: str, fn: Callable[[Array, Array], QPSolution]) -> None:
    """Add a solver: ``fn(A, b)`` solves min ||c||^2/2 s.t. A c >= b."""
    SOLVERS[name] = (module, fn)


def available_solvers() -> list[str]:
    return [k for k, (mod, _) in SOLVERS.items() if importlib.util.find_spec(mod) is not None]


def first_available(names: tuple[str, ...]) -> str:
    """The first installed solver of ``names`` (the last one if none is)."""
    have = set(available_solvers())
    return next((n for n in names if n in have), names[-1])


def check_solver(name: str) -> str:
    if name not in SOLVERS:
        raise InputError(f"unknown solver {name!r}; choose one of {', '.join(SOLVERS)}")
    if importlib.util.find_spec(SOLVERS[name][0]) is None:
        raise InputError(
            f"solver {name!r} is not installed (pip install {SOLVERS[name][0]}); "
            f"installed: {', '.join(available_solvers()) or 'none'}"
        )
    return name


def solve_qp(A: Array, b: Array, solver: str = "quadprog",
             time_limit: float | None = None) -> QPSolution:
    """Solve min ||c||^2/2 s.t. A c >= b with the named solver.

    ``time_limit`` (seconds) goes to solvers that take one (DAQP; status
    "error" when it runs out); the others cannot be interrupted."""
    fn = SOLVERS[check_solver(solver)][1]
    try:
        sol = fn(A, b, time_limit=time_limit) if time_limit is not None and \
            solver in TIMED_SOLVERS else fn(A, b)
    except Exception as exc:  # a solver crash is a status, not a crash of the search
        return QPSolution("error", None, f"{type(exc).__name__}: {exc}", solver)
    if sol.x is not None and not np.all(np.isfinite(sol.x)):
        return QPSolution("error", None, "non-finite solution", solver)
    return sol
