"""The chain's per-state caches: bounds in entries and in bytes, and that eviction changes no number."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from objslam_mapper.config import DetectionConfig, SamplerConfig
from objslam_mapper.inference.association import enumerate_associations
from objslam_mapper.inference.caches import fifo, lru, lru_bytes, nbytes, remember
from objslam_mapper.inference.target import AssociationTarget, TargetOptions
from objslam_mapper.inference.tracklets import tracklets_of_problem
from tests.objslam_mapper.association_scenes import problem_of, simulate


@dataclass(frozen=True)
class _Held:
    a: np.ndarray
    rest: tuple


def test_nbytes_counts_the_arrays_in_nested_tuples_and_dataclasses():
    held = _Held(np.zeros((10, 3)), (np.zeros(4, dtype=np.bool_), [np.ones(2)], "name", 7))
    assert nbytes(held) == 240 + 4 + 16
    assert nbytes((np.zeros(5, dtype=np.int64), held)) == 40 + 260
    assert nbytes("not an array") == 0


@given(st.lists(st.tuples(st.integers(0, 9), st.integers(1, 40)), max_size=60))
def test_a_byte_bounded_cache_holds_the_most_recent_values_that_fit(ops):
    """Against a plain model: after each store, the cache holds the most recently stored or
    read keys whose sizes fit in the bound, newest first, and never more bytes than it."""
    bound = 64 * 8
    cache = lru_bytes(bound)
    recent: list[int] = []  # keys, newest last
    sizes: dict[int, int] = {}
    for key, length in ops:
        if key in cache:
            assert cache.get(key) is not None  # a read renews the key, as it does in the model
            recent.remove(key)
            recent.append(key)
        value = np.zeros(length)
        assert remember(cache, key, value) is value
        if key in recent:
            recent.remove(key)
        recent.append(key)
        sizes[key] = value.nbytes
        assert cache.currsize <= bound
        kept, total = [], 0
        for k in reversed(recent):
            if total + sizes[k] > bound:
                break
            kept.append(k)
            total += sizes[k]
        assert sorted(cache) == sorted(kept)
        recent = [k for k in recent if k in cache]


def test_a_value_larger_than_its_cache_is_returned_and_not_kept():
    cache = lru_bytes(100)
    big = np.zeros(20)
    assert remember(cache, "big", big) is big
    assert "big" not in cache and cache.currsize == 0


def test_an_entry_bounded_lru_renews_on_read_and_a_fifo_does_not():
    renewed, first_in = lru(2), fifo(2)
    for cache in (renewed, first_in):
        remember(cache, "a", 1)
        remember(cache, "b", 2)
        assert cache.get("a") == 1
        remember(cache, "c", 3)
    assert sorted(renewed) == ["a", "c"]
    assert sorted(first_in) == ["b", "c"]


@pytest.fixture(scope="module")
def scene():
    problem = problem_of(simulate())
    return problem, tracklets_of_problem(problem).tracklets


def test_sightings_evicted_by_the_byte_bound_come_back_to_the_same_target(scene):
    """A target whose sightings cache holds about one state gives every state the log target
    an unbounded one gives, in any order of visits, and keeps within its bound."""
    problem, tracklets = scene
    detection = DetectionConfig(max_range_m=3.5)
    labels = [t.label for t in tracklets]
    states = list(enumerate_associations(labels))[:14]
    roomy = AssociationTarget(problem, tracklets, TargetOptions(detection=detection))
    first = {s: roomy(s) for s in states}
    one_state = nbytes(roomy._sights[states[-1]])
    assert one_state > 0
    tight = AssociationTarget(
        problem, tracklets, TargetOptions(detection=detection, sightings_cache_bytes=int(1.5 * one_state))
    )
    order = np.random.default_rng(0).permutation(len(states)).tolist() * 2
    for i in order:
        assert tight(states[i]) == pytest.approx(first[states[i]], abs=1e-9)
        assert tight._sights.currsize <= 1.5 * one_state
    assert len(tight._sights) < len(roomy._sights)


def test_the_sampler_setting_reaches_the_target_in_bytes():
    assert TargetOptions.of(SamplerConfig(sightings_cache_mb=3)).sightings_cache_bytes == 3 * 2**20
