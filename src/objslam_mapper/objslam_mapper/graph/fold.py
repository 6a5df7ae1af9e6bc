"""Short-lived objects folded into the pose band before the objects' Schur complement.

An object seen from poses a..b couples only those poses, so eliminating it first (its
own 5x5 block, inverted alone) adds ``B_j C_j^-1 B_j^T`` to the pose block within a band
of half-width ``3 (b - a + 1) - 1``; the dense Schur complement (5K x 5K from 3N rows)
is then over the objects left. A chain started from singletons holds a hundred or more
tracklets as objects on a long run, most seen over a few dozen poses, and there the
complement was most of a solve (``loop`` seed 13: 40-47 ms a factorization at 159 objects
on 900 poses). Which objects fold is chosen per layout by a cost model of the
factorization's steps (nanoseconds, fitted to LAPACK and numpy timings on this machine
class; only the choice depends on it, the numbers agree to rounding), so a map of long-lived objects
keeps the plain path. The algebra is exact either way (docs/method.md, "Why it is fast").
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import numpy as np
from numpy.typing import NDArray

from objslam_mapper.graph.bins import bin_sum
from objslam_mapper.graph.problem import OBJECT_DIM, POSE_DIM

if TYPE_CHECKING:
    from objslam_mapper.graph.layout import Layout

POSE_BAND = 5  # upper bandwidth of the pose block alone: pose i couples with pose i+1 only
_WORTH = 0.8


class FoldPlan(NamedTuple):
    """Which objects fold into the pose band, and where their terms go."""

    folded: NDArray[np.int64]  # (F,) objects eliminated into the band
    kept: NDArray[np.int64]  # (K - F,) objects left to the Schur complement
    half_width: int  # upper bandwidth of the pose block after folding
    slice_order: NDArray[np.int64]  # folded objects' slices (layout order), sorted by observation
    obs_starts: NDArray[np.int64]  # where each observation's run starts in slice_order
    obs_object: NDArray[np.int64]  # (O,) folded object (index into ``folded``) of each observation
    obs_pose: NDArray[np.int64]  # (O,) pose of each observation; observations grouped by object
    object_starts: NDArray[np.int64]  # (F,) where each folded object's observations start
    pair_first: NDArray[np.int64]  # (P,) observation pairs of one object, first pose <= second
    pair_second: NDArray[np.int64]
    pair_keep: NDArray[np.bool_]  # (P * 9,) entries of the pairs' 3x3 blocks on or above the diagonal
    pair_bins: NDArray[np.int64]  # flat index in the (half_width + 1, 3N) band of each kept entry
    kept_slices: NDArray[np.int64]  # slices (layout order) of the kept objects
    kept_bins: NDArray[np.int64]  # (3, 5, len(kept_slices)) flat index in the (3N, 5 (K - F)) block


def _cost_ns(rows: int, half_width: int, dense: int, fold_entries: int) -> float:
    """Estimated nanoseconds of one factorization: banded Cholesky, the banded solve for the
    dense columns, W^T W, the complement's Cholesky, and the folding itself."""
    return (
        10.0 * rows * half_width
        + rows * dense * (7.0 + 0.065 * half_width)
        + 0.02 * rows * dense**2
        + 0.02 * dense**3
        + 5.0 * fold_entries
    )


def _half_width(limit: int) -> int:
    """The pose block's upper bandwidth with every object seen over at most ``limit`` poses folded."""
    return max(POSE_BAND, POSE_DIM * limit - 1)


def _observations(layout: Layout) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
    """Distinct (object, pose) pairs, grouped by object, poses ascending: each slice's pair,
    and each pair's object and pose."""
    keys = layout.object_of * layout.n_poses + layout.pose_of
    obs_keys, obs_of_slice = np.unique(keys, return_inverse=True)
    obs_object, obs_pose = np.divmod(obs_keys, layout.n_poses)
    return obs_of_slice, obs_object, obs_pose


def _spans(layout: Layout) -> NDArray[np.int64]:
    """(K,) how many poses each object's sightings span, first to last."""
    first = np.minimum.reduceat(layout.pose_of, layout.starts)
    last = np.maximum.reduceat(layout.pose_of, layout.starts)
    return last - first + 1


def fold_plan(layout: Layout) -> FoldPlan | None:
    """The cheapest fold of ``layout``'s objects by the cost model; None: fold none."""
    k = layout.n_objects
    if not k:
        return None
    span = _spans(layout)
    limits = np.unique(span)
    rows, extra = POSE_DIM * layout.n_poses, layout.n_calib + 1
    kept = [OBJECT_DIM * int(np.count_nonzero(span > limit)) + extra for limit in limits]
    # A fold must promise a fifth off: below that the model's error is the difference.
    best_cost = _WORTH * _cost_ns(rows, POSE_BAND, OBJECT_DIM * k + extra, 0)
    # Folding only adds entries to a fold's cost: where no fold wins without them, none does,
    # and the observations (a sort of every slice) need not be counted.
    bounds = [_cost_ns(rows, _half_width(int(limit)), dense, 0) for limit, dense in zip(limits, kept, strict=True)]
    if min(bounds) >= best_cost:
        return None
    observations = _observations(layout)
    seen = np.bincount(observations[1], minlength=k)  # poses each object is seen from
    entries = 9 * seen * (seen + 1) // 2
    best: int | None = None
    for limit, dense in zip(limits, kept, strict=True):
        cost = _cost_ns(rows, _half_width(int(limit)), dense, int(entries[span <= limit].sum()))
        if cost < best_cost:
            best_cost, best = cost, int(limit)
    return None if best is None else _plan(layout, span <= best, best, observations)


def fold_up_to(layout: Layout, limit: int) -> FoldPlan:
    """The plan that folds every object seen over at most ``limit`` poses (of any cost)."""
    return _plan(layout, _spans(layout) <= limit, limit, _observations(layout))


def _plan(
    layout: Layout,
    short: NDArray[np.bool_],
    limit: int,
    observations: tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]],
) -> FoldPlan:
    """The plan folding the ``short`` objects, each seen over at most ``limit`` poses."""
    obs_of_slice, obs_object, obs_pose = observations
    folded, kept = np.flatnonzero(short), np.flatnonzero(~short)
    rows = POSE_DIM * layout.n_poses
    half_width = _half_width(limit)
    is_folded = np.zeros(layout.n_objects, dtype=bool)
    is_folded[folded] = True
    # Observations of folded objects, renumbered; their slices sorted by observation.
    obs_folded = is_folded[obs_object]
    renumber = np.cumsum(obs_folded) - 1
    folded_slices = np.flatnonzero(is_folded[layout.object_of])
    slice_obs = renumber[obs_of_slice[folded_slices]]
    order = np.argsort(slice_obs, kind="stable")
    slice_order = folded_slices[order]
    obs_starts = np.flatnonzero(np.diff(slice_obs[order], prepend=-1))
    index_of = np.full(layout.n_objects, -1)
    index_of[folded] = np.arange(len(folded))
    f_object = index_of[obs_object[obs_folded]]
    f_pose = obs_pose[obs_folded]
    object_starts = np.flatnonzero(np.diff(f_object, prepend=-1))
    counts = np.diff(np.append(object_starts, len(f_object)))
    # Every pair (first <= second) of one object's observations.
    first_list, second_list = [], []
    for start, count in zip(object_starts, counts, strict=True):
        i, j = np.triu_indices(int(count))
        first_list.append(start + i)
        second_list.append(start + j)
    pair_first = np.concatenate(first_list) if first_list else np.zeros(0, dtype=np.int64)
    pair_second = np.concatenate(second_list) if second_list else np.zeros(0, dtype=np.int64)
    a, b = np.meshgrid(np.arange(POSE_DIM), np.arange(POSE_DIM), indexing="ij")
    row = POSE_DIM * f_pose[pair_first][:, None, None] + a
    col = POSE_DIM * f_pose[pair_second][:, None, None] + b
    keep = (row <= col).ravel()
    pair_bins = ((half_width + row - col) * rows + col).ravel()[keep]
    kept_index = np.full(layout.n_objects, -1)
    kept_index[kept] = np.arange(len(kept))
    kept_slices = np.flatnonzero(~is_folded[layout.object_of])
    p3 = np.arange(POSE_DIM)[:, None, None]
    o5 = np.arange(OBJECT_DIM)[None, :, None]
    kept_bins = (POSE_DIM * layout.pose_of[kept_slices] + p3) * (OBJECT_DIM * len(kept)) + (
        OBJECT_DIM * kept_index[layout.object_of[kept_slices]] + o5
    )
    return FoldPlan(
        folded=folded,
        kept=kept,
        half_width=half_width,
        slice_order=slice_order,
        obs_starts=obs_starts,
        obs_object=f_object,
        obs_pose=f_pose,
        object_starts=object_starts,
        pair_first=pair_first,
        pair_second=pair_second,
        pair_keep=keep,
        pair_bins=pair_bins,
        kept_slices=kept_slices,
        kept_bins=kept_bins.astype(np.int64, copy=False),
    )


class Folded(NamedTuple):
    """The folded objects' share of the pose system, and what their steps need."""

    band: NDArray[np.float64]  # (half_width + 1, 3N): B_f C_f^-1 B_f^T in upper band storage
    grad_pose: NDArray[np.float64]  # (3N,): B_f C_f^-1 g_f
    log_det: float  # log |C_f|
    whitened: NDArray[np.float64]  # (O, 3, 5): each observation's B block times L^-T
    inv_chol: NDArray[np.float64]  # (F, 5, 5): L^-1 of each folded object (C = L L^T)
    whitened_grad: NDArray[np.float64]  # (F, 5): L^-1 g of each folded object


def fold(
    plan: FoldPlan,
    cross: NDArray[np.float64],
    object_diag: NDArray[np.float64],
    grad_object: NDArray[np.float64],
    n_poses: int,
) -> Folded:
    """Eliminate ``plan.folded``: ``cross`` (3, 5, A) the slices' pose-object blocks,
    ``object_diag`` (K, 5, 5) (damped if the step is) and ``grad_object`` (K, 5) all objects'.

    Raises LinAlgError if a folded object's block is not positive definite.
    """
    rows = POSE_DIM * n_poses
    chol = np.linalg.cholesky(object_diag[plan.folded])
    inv_chol = np.linalg.inv(chol)
    log_det = 2.0 * float(np.sum(np.log(np.diagonal(chol, axis1=1, axis2=2))))
    blocks = np.add.reduceat(np.moveaxis(cross[:, :, plan.slice_order], 2, 0), plan.obs_starts, axis=0)
    whitened = blocks @ np.swapaxes(inv_chol, 1, 2)[plan.obs_object]
    pairs = whitened[plan.pair_first] @ np.swapaxes(whitened[plan.pair_second], 1, 2)
    whitened_grad = np.einsum("fij,fj->fi", inv_chol, grad_object[plan.folded])
    pose_terms = np.einsum("oik,ok->oi", whitened, whitened_grad[plan.obs_object])
    grad_bins = (POSE_DIM * plan.obs_pose[:, None] + np.arange(POSE_DIM)).ravel()
    return Folded(
        band=bin_sum(plan.pair_bins, pairs.ravel()[plan.pair_keep], (plan.half_width + 1, rows)),
        grad_pose=bin_sum(grad_bins, pose_terms, (rows,)),
        log_det=log_det,
        whitened=whitened,
        inv_chol=inv_chol,
        whitened_grad=whitened_grad,
    )


def folded_steps(plan: FoldPlan, folded: Folded, step_pose: NDArray[np.float64]) -> NDArray[np.float64]:
    """(F, 5) the folded objects' steps from the poses': ``-C^-1 (g + B^T step_pose)``."""
    along = np.einsum("oik,oi->ok", folded.whitened, step_pose.reshape(-1, POSE_DIM)[plan.obs_pose])
    per_object = np.add.reduceat(along, plan.object_starts, axis=0)
    return -np.einsum("fji,fj->fi", folded.inv_chol, folded.whitened_grad + per_object)
