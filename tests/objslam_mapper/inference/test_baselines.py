"""objslam_mapper.inference.baselines: fixed associations mapped by the same factor graph."""

from __future__ import annotations

import numpy as np
import pytest

from objslam_common.catalog import load_catalog
from objslam_mapper.config import SamplerConfig
from objslam_mapper.inference.baselines import (
    BaselineError,
    GreedyOptions,
    build_baseline_map,
    greedy_association,
    map_of_association,
    no_association,
)
from objslam_mapper.inference.tracklets import tracklets_of_problem
from objslam_mapper.synthetic import SyntheticObject
from tests.objslam_mapper.association_scenes import GREEN, POSTER_FRAMES, RED_A, problem_of, simulate, with_poster

# Two metres from RED_A along the drive, so both are seen on the way out.
RED_FAR = SyntheticObject("red", (3.5, 1.2, 0.0), (0.31, 0.59))


def _scene(objects=(RED_A, RED_FAR, GREEN), images=None):
    run = simulate(objects)
    problem = problem_of(run, images)
    tracklets = tracklets_of_problem(problem).tracklets
    return run, problem, tracklets


def _true_objects(run, problem, tracklets) -> list[int]:
    """The true object of each tracklet (every tracklet of these scenes is pure)."""
    truth = []
    for t in tracklets:
        ids = {
            run.slice_object[problem.measurement_image[m]][problem.measurement_slot[m]] for m in t.measurement_indices
        }
        assert len(ids) == 1
        truth.append(ids.pop())
    return truth


def test_gate_is_the_chi_square_quantile_with_two_dof():
    assert GreedyOptions(0.99).gate_chi2 == pytest.approx(9.2103, abs=1e-4)
    assert GreedyOptions(0.95).gate_chi2 == pytest.approx(5.9915, abs=1e-4)


def test_none_gives_one_object_per_tracklet():
    run, problem, tracklets = _scene()
    # RED_A is seen out and back: two tracklets of one object, which "none" keeps apart.
    truth = _true_objects(run, problem, tracklets)
    assert truth.count(0) == 2
    state = no_association(tracklets)
    assert state.groups == tuple((t,) for t in range(len(tracklets))) and not state.clutter
    built = map_of_association(problem, tracklets, state, SamplerConfig())
    assert len(built.objects) + len(built.rejected) == len(tracklets)
    assert sorted(o.measurement_count for o in [*built.objects, *built.rejected]) == sorted(len(t) for t in tracklets)


def test_greedy_merges_one_objects_tracklets_and_keeps_objects_2m_apart():
    run, problem, tracklets = _scene()
    truth = _true_objects(run, problem, tracklets)
    state = greedy_association(problem, tracklets)
    got = sorted(sorted(truth[t] for t in group) for group in state.groups)
    assert got == [[0, 0], [1], [2]]  # both RED_A tracklets together, RED_FAR apart

    built = map_of_association(problem, tracklets, state, SamplerConfig())
    assert len(built.objects) == 3 and not built.rejected
    reds = sorted((o for o in built.objects if o.label == "red"), key=lambda o: o.position_m[0])
    for obj, true in zip(reds, (RED_A, RED_FAR), strict=True):
        # The map is anchored at the first (true) pose, so it is in the true frame up to drift.
        assert np.hypot(*(np.subtract(obj.position_m[:2], true.location_m[:2]))) < 0.15
        assert obj.existence_probability == 1.0


def test_greedy_gates_on_a_solve_that_stopped_short_of_convergence(monkeypatch):
    """A stalled solve still says where the tracklet lies; skipping it had left every later
    tracklet a new object (each later solve carried the stalled one's object along)."""
    import dataclasses

    import objslam_mapper.inference.start as start

    solve = start.solve_with_backend

    def stalled(*args, **kwargs):
        return dataclasses.replace(solve(*args, **kwargs), converged=False)

    monkeypatch.setattr(start, "solve_with_backend", stalled)
    run, problem, tracklets = _scene()
    truth = _true_objects(run, problem, tracklets)
    state = greedy_association(problem, tracklets)
    assert sorted(sorted(truth[t] for t in group) for group in state.groups) == [[0, 0], [1], [2]]


def test_greedy_leaves_a_tracklet_it_cannot_place_out_of_every_later_solve(monkeypatch):
    """A tracklet whose object the solve places only within metres joins nothing (with such a
    covariance every object of its class is inside the gate) and is not carried in later solves."""
    import dataclasses

    import objslam_mapper.inference.start as start

    solve = start.solve_with_backend
    solved: list[list[set[int]]] = []

    def vague(problem, groups, **kwargs):
        solution = solve(problem, groups, **kwargs)
        solved.append([set(map(int, g)) for g in groups])
        wide = dataclasses.replace(solution.objects[-1], location_cov=np.diag([25.0, 25.0, 1.0]))
        return dataclasses.replace(solution, objects=(*solution.objects[:-1], wide))

    monkeypatch.setattr(start, "solve_with_backend", vague)
    run, problem, tracklets = _scene()
    state = greedy_association(problem, tracklets)
    assert state.n_objects == len(tracklets)  # the RED_A tracklets too stay apart
    assert solved  # the second RED_A tracklet had a candidate, so a solve
    for k, groups in enumerate(solved):
        new = groups[-1]
        later = [g for call in solved[k + 1 :] for g in call]
        assert all(not new & g for g in later)
    # With a bound wider than the covariance, the same solves join RED_A's tracklets as before.
    state = greedy_association(problem, tracklets, GreedyOptions(max_location_stddev_m=6.0))
    truth = _true_objects(run, problem, tracklets)
    assert [0, 0] in [sorted(truth[t] for t in group) for group in state.groups]


def test_a_zero_gate_merges_nothing():
    _run, problem, tracklets = _scene()
    state = greedy_association(problem, tracklets, GreedyOptions(gate_probability=0.0))
    assert state.n_objects == len(tracklets)


def test_baselines_keep_a_distractor_the_sampler_could_call_clutter():
    run = simulate((RED_A, GREEN))
    images = with_poster(run)
    built = build_baseline_map(run.odometry, images, load_catalog(), "greedy")
    assert built.diagnostics["association"] == "greedy"
    # The poster's slices (4 images) chain into a tracklet that greedy has to make an object of.
    held = [o for o in [*built.objects, *built.rejected] if o.measurement_count == len(POSTER_FRAMES)]
    assert len(held) == 1 and held[0].label == "green"


def test_unknown_baseline_is_an_error():
    run = simulate((RED_A,))
    with pytest.raises(BaselineError, match="unknown baseline"):
        build_baseline_map(run.odometry, run.images, load_catalog(), "sampler")
