"""The naive baseline of ``objslam bench mapper``: one fresh GTSAM solve per association."""

from __future__ import annotations

import time
from collections.abc import Sequence

from numpy.typing import ArrayLike

from objslam_mapper.graph.gtsam_backend import solve_gtsam
from objslam_mapper.graph.problem import GraphProblem
from objslam_tools.errors import ToolsError


def time_naive_solves(
    problem: GraphProblem, groups_list: Sequence[Sequence[ArrayLike]], max_seconds: float
) -> tuple[float, int]:
    """Seconds per naive solve and how many were timed (the benchmark's baseline).

    The naive baseline: for each association of ``groups_list`` in turn, a fresh graph with
    one CustomFactor per detection, solved cold by GTSAM's own Levenberg-Marquardt, with its
    evidence (one elimination). Stops after the first solve that ends past ``max_seconds``
    (at least one solve).
    """
    if not groups_list:
        raise ToolsError("no associations to time")
    start = time.perf_counter()
    count = 0
    for groups in groups_list:
        solve_gtsam(problem, groups, per_detection=True, drive="optimizer")
        count += 1
        if time.perf_counter() - start >= max_seconds:
            break
    return (time.perf_counter() - start) / count, count
