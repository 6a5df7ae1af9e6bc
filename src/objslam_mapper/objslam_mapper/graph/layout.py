"""The index arrays of one association's factor graph: which measurement belongs to which
object and pose, where each block of the normal equations goes, and the graph's log-normalizer."""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from objslam_mapper.graph.fold import FoldPlan, fold_plan
from objslam_mapper.graph.problem import OBJECT_DIM, POSE_DIM, GraphError, GraphProblem


@dataclass(frozen=True)
class Layout:
    """Index arrays of one association, fixed for the whole solve (measurement axis last)."""

    n_poses: int
    n_calib: int  # 3 with the odometry calibration as a variable, else 0
    groups: tuple[NDArray[np.int64], ...]
    measurements: NDArray[np.int64]  # (A,) assigned measurements, grouped by object
    object_of: NDArray[np.int64]
    pose_of: NDArray[np.int64]
    labels: NDArray[np.int64]  # (K,) label index of each object
    priors: NDArray[np.int64]  # (K,) prior row of each object (its class's unless given)
    pose_bins: NDArray[np.int64]  # (3, 3, A) bins of the per-slice pose blocks in (N, 3, 3)
    pose_grad_bins: NDArray[np.int64]  # (3, A) bins in (N, 3)
    starts: NDArray[np.int64]  # (K,) where each object's run of measurements starts
    cross_bins: NDArray[np.int64]  # (3, 5, A) bins in the (3N, 5K) pose-object block
    cross_unique: bool  # no image saw one object twice: the cross blocks need no summing

    @property
    def n_objects(self) -> int:
        return len(self.groups)

    @functools.cached_property
    def first_pose(self) -> NDArray[np.int64]:
        """(K,) the first pose that saw each object: its pose-object block is zero above it."""
        if not self.n_objects:
            return np.zeros(0, dtype=np.int64)
        return np.minimum.reduceat(self.pose_of, self.starts)

    @functools.cached_property
    def sparse(self) -> SparsePattern:
        return SparsePattern.of(self)

    @functools.cached_property
    def fold_plan(self) -> FoldPlan | None:
        """The objects the dense path folds into the pose band (:mod:`.fold`); None: none."""
        return fold_plan(self)


def layout_of(problem: GraphProblem, groups: Sequence[ArrayLike], priors: ArrayLike | None = None) -> Layout:
    """Validate an association (one array of measurement indices per object) and index it.

    ``priors[j]`` is the prior row of object j (``problem.prior_mean``); default its class's.
    """
    arrays = tuple(np.asarray(g, dtype=np.int64).reshape(-1) for g in groups)
    sizes = np.array([len(g) for g in arrays], dtype=np.int64)
    if np.any(sizes == 0):
        raise GraphError("every group must hold at least one measurement")
    measurements = np.concatenate(arrays) if arrays else np.zeros(0, dtype=np.int64)
    if len(measurements) and (measurements.min() < 0 or measurements.max() >= problem.measurement_count):
        raise GraphError(f"measurement indices must lie in [0, {problem.measurement_count})")
    if np.any(np.bincount(measurements, minlength=problem.measurement_count) > 1):
        raise GraphError("a measurement is assigned to more than one object (or twice to one)")
    object_of = np.repeat(np.arange(len(arrays), dtype=np.int64), sizes)
    label_of = problem.measurement_label[measurements]
    labels = label_of[np.cumsum(sizes) - sizes] if len(arrays) else np.zeros(0, dtype=np.int64)
    mixed = label_of != labels[object_of]
    if np.any(mixed):
        raise GraphError(f"group {int(object_of[np.argmax(mixed)])} mixes classes; an object holds one class")
    if priors is None:
        prior_rows = labels.copy()
    else:
        prior_rows = np.asarray(priors, dtype=np.int64).reshape(-1)
        if len(prior_rows) != len(arrays):
            raise GraphError(f"{len(prior_rows)} prior rows for {len(arrays)} groups")
        if len(prior_rows) and (prior_rows.min() < 0 or prior_rows.max() >= len(problem.prior_mean)):
            raise GraphError(f"prior rows must lie in [0, {len(problem.prior_mean)})")
    for g in arrays:
        g.flags.writeable = False
    pose_of = problem.measurement_pose[measurements]
    n_cols = OBJECT_DIM * len(arrays)
    p3, o5 = np.arange(POSE_DIM)[:, None], np.arange(OBJECT_DIM)[:, None]
    return Layout(
        n_poses=problem.pose_count,
        n_calib=problem.calibration_dim,
        groups=arrays,
        measurements=measurements,
        object_of=object_of,
        pose_of=pose_of,
        labels=labels,
        priors=prior_rows,
        pose_bins=(POSE_DIM * pose_of + p3)[:, None, :] * POSE_DIM + p3.T[:, :, None],
        pose_grad_bins=POSE_DIM * pose_of + p3,
        starts=np.cumsum(sizes) - sizes,
        cross_bins=(POSE_DIM * pose_of + p3)[:, None, :] * n_cols + (OBJECT_DIM * object_of + o5)[None, :, :],
        cross_unique=not len(measurements) or np.bincount(pose_of * len(arrays) + object_of).max() == 1,
    )


def graph_log_normalizer(problem: GraphProblem, layout: Layout) -> float:
    """Sum of the log-normalizers of every factor of the association's graph."""
    return (
        problem.trajectory_log_normalizer
        + float(np.sum(problem.measurement_log_normalizer[layout.measurements]))
        + float(np.sum(problem.prior_log_normalizer[layout.priors]))
    )


@dataclass(frozen=True)
class SparsePattern:
    """CSC structure of the whole of Lambda, and where each block entry's value lands in it.

    The values of one linearization are concatenated in the order of ``_sparse_values``
    and summed into ``data`` by ``slot`` (repeated entries, e.g. two slices of one object
    in one image, add up).
    """

    dimension: int
    indices: NDArray[np.int32]
    indptr: NDArray[np.int32]
    slot: NDArray[np.int64]
    diagonal_slots: NDArray[np.int64]  # data positions of the diagonal, in variable order

    @classmethod
    def of(cls, layout: Layout) -> SparsePattern:
        n, k, nc = layout.n_poses, layout.n_objects, layout.n_calib
        dim = POSE_DIM * n + OBJECT_DIM * k + nc
        a3 = np.arange(POSE_DIM)
        p = np.arange(n)[:, None, None]
        diag_r, diag_c = 3 * p + a3[None, :, None], 3 * p + a3[None, None, :]
        q = np.arange(max(n - 1, 0))[:, None, None]
        off_r, off_c = 3 * q + a3[None, :, None], 3 * q + 3 + a3[None, None, :]
        cross_r = POSE_DIM * layout.pose_of[None, None, :] + a3[:, None, None]
        cross_c = POSE_DIM * n + OBJECT_DIM * layout.object_of[None, None, :] + np.arange(OBJECT_DIM)[None, :, None]
        cross_r, cross_c = np.broadcast_arrays(cross_r, cross_c)
        o = np.arange(k)[:, None, None]
        a5 = np.arange(OBJECT_DIM)
        obj_r = POSE_DIM * n + OBJECT_DIM * o + a5[None, :, None]
        obj_c = POSE_DIM * n + OBJECT_DIM * o + a5[None, None, :]
        obj_r, obj_c = np.broadcast_arrays(obj_r, obj_c)
        diag_r, diag_c = np.broadcast_arrays(diag_r, diag_c)
        off_r, off_c = np.broadcast_arrays(off_r, off_c)
        ac = POSE_DIM * n + OBJECT_DIM * k + np.arange(nc)
        pc_r, pc_c = np.broadcast_arrays(3 * p + a3[None, :, None], ac[None, None, :])
        cc_r, cc_c = np.broadcast_arrays(ac[:, None], ac[None, :])
        blocks_r = (diag_r, off_r, off_c, cross_r, cross_c, obj_r, pc_r, pc_c, cc_r)
        blocks_c = (diag_c, off_c, off_r, cross_c, cross_r, obj_c, pc_c, pc_r, cc_c)
        rows = np.concatenate([x.ravel() for x in blocks_r])
        cols = np.concatenate([x.ravel() for x in blocks_c])
        keys, slot = np.unique(cols.astype(np.int64) * dim + rows, return_inverse=True)
        indices = (keys % dim).astype(np.int32)
        counts = np.bincount(keys // dim, minlength=dim)
        indptr = np.concatenate([[0], np.cumsum(counts)]).astype(np.int32)
        diag_keys = np.arange(dim, dtype=np.int64) * (dim + 1)
        return cls(dim, indices, indptr, slot, np.searchsorted(keys, diag_keys))
