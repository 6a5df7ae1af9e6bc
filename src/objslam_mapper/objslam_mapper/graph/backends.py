"""One entry point for a known-association solve, whichever backend ``solver.backend`` names.

``fast`` is :func:`objslam_mapper.graph.solver.solve` (numpy, the default); ``gtsam`` is
:func:`objslam_mapper.graph.gtsam_backend.solve_gtsam` (the same model solved by GTSAM, with
its default graph and drive). Both return the same :class:`~objslam_mapper.graph.solver.GraphSolution`.
GTSAM is imported only when it is asked for.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from numpy.typing import ArrayLike

from objslam_mapper.graph.problem import GraphProblem
from objslam_mapper.graph.solver import GraphSolution, solve


def solve_with_backend(
    problem: GraphProblem,
    groups: Sequence[ArrayLike],
    warm_start: GraphSolution | None = None,
    **kwargs: Any,
) -> GraphSolution:
    """``solve(problem, groups, warm_start, **kwargs)`` by the backend of ``problem.solver.backend``.

    ``kwargs`` are those of :func:`objslam_mapper.graph.solver.solve` (``with_covariances``,
    ``max_iterations``); the GTSAM backend also takes its own (``drive``, ``per_detection``, ...).
    """
    if problem.solver.backend == "gtsam":
        from objslam_mapper.graph.gtsam_backend import solve_gtsam

        return solve_gtsam(problem, groups, warm_start, **kwargs)
    return solve(problem, groups, warm_start, **kwargs)
