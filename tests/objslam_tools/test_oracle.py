"""objslam_tools.oracle: slices simulated from the ground truth are assigned to their objects."""

from __future__ import annotations

import numpy as np
import pytest

from objslam_common.mount import CameraMount
from objslam_common.records import ImageSlices, SliceMeasurement
from objslam_mapper.model.slice_model import predict_slices
from objslam_tools.ground_truth import GroundTruth, GroundTruthObject
from objslam_tools.oracle import OracleOptions, oracle_assignment, truth_residual_chi2
from objslam_tools.trajectory import PoseTrack
from tests.objslam_tools import synthetic_scene as scene

TRUTH = GroundTruth(objects=scene.OBJECTS, distractors=scene.DISTRACTORS)
STAMPS, POSES = scene.ground_truth_poses()
TRACK = PoseTrack(STAMPS, POSES)


def _slice(label: str, values, noise=(0.0, 0.0, 0.0, 0.0)) -> SliceMeasurement:
    b, w, lo, hi = np.asarray(values) + np.asarray(noise)
    return SliceMeasurement(label, 1.0, float(b), float(max(w, 1e-3)), float(lo), float(max(hi, lo)))


def _simulated(rng: np.random.Generator, truth: GroundTruth = TRUTH):
    """Per image: every visible object's slice with noise, plus a clutter slice; and the true ids."""
    images, expected = [], []
    for stamp, pose in zip(STAMPS[::3], POSES[::3], strict=True):
        objs = truth.objects
        pred = predict_slices(
            pose, [o.position_m for o in objs], [o.size_m for o in objs], CameraMount(), jacobians=False
        )
        slices, ids = [], []
        for o, values in zip(objs, pred.values, strict=True):
            slices.append(_slice(o.label, values, rng.normal(0.0, [0.01, 0.005, 0.01, 0.01])))
            ids.append(o.id)
        # A yellow poster (no yellow object exists) and a red blob far from both reds' bearings.
        slices.append(_slice("yellow", (0.3, 0.2, -0.1, 0.2)))
        ids.append(None)
        reds = pred.values[[k for k, o in enumerate(objs) if o.label == "red"], 0]
        away = float(np.angle(np.exp(1j * (reds.mean() + np.pi))))
        if np.min(np.abs(np.angle(np.exp(1j * (reds - away))))) > 0.6:
            slices.append(_slice("red", (away, 0.05, -0.2, 0.1)))
            ids.append(None)
        order = rng.permutation(len(slices))
        images.append(ImageSlices(int(stamp), tuple(slices[k] for k in order)))
        expected.append(tuple(ids[k] for k in order))
    return images, expected


def test_simulated_slices_are_assigned_to_their_objects():
    images, expected = _simulated(np.random.default_rng(1))
    assert oracle_assignment(images, TRUTH, TRACK) == expected


def test_neighbouring_same_class_objects_are_kept_apart():
    # Two reds almost on one line of sight. The near red's slice is noisy towards the far red's bearing:
    # nearest-first would give both slices to the far red; the joint assignment keeps one each.
    start = POSES[0]
    heading = start[2] + 0.5
    near = start[:2] + 1.5 * np.array([np.cos(heading), np.sin(heading)])
    far = start[:2] + 2.2 * np.array([np.cos(heading + 0.08), np.sin(heading + 0.08)])
    objs = (
        GroundTruthObject(7, "red", (near[0], near[1], 0.0), (0.3, 0.6)),
        GroundTruthObject(8, "red", (far[0], far[1], 0.0), (0.3, 0.6)),
    )
    pred = predict_slices(start, [o.position_m for o in objs], [o.size_m for o in objs], CameraMount(), jacobians=False)
    (b7, w7, lo7, hi7), (b8, w8, lo8, hi8) = pred.values
    delta = b8 - b7
    top = 0.5 * (hi7 + hi8)
    s7 = _slice("red", (b7 + 0.6 * delta, w7, lo7, top))
    s8 = _slice("red", (b8 + 0.2 * delta, w8, lo8, top))
    got = oracle_assignment([ImageSlices(int(STAMPS[0]), (s7, s8))], GroundTruth(objects=objs), TRACK)
    assert got == [(7, 8)]


def test_split_blob_goes_to_the_same_object():
    pose = POSES[0]
    o = scene.OBJECTS[2]
    b, w, lo, hi = predict_slices(pose, o.position_m, o.size_m, CameraMount(), jacobians=False).values[0]
    halves = (_slice(o.label, (b - w / 4, w / 2, lo, hi)), _slice(o.label, (b + w / 4, w / 2, lo, hi)))
    assert oracle_assignment([ImageSlices(int(STAMPS[0]), halves)], TRUTH, TRACK) == [(o.id, o.id)]


def test_wrong_elevation_or_stamp_outside_is_unexplained():
    pose = POSES[0]
    o = scene.OBJECTS[3]
    b, w, lo, hi = predict_slices(pose, o.position_m, o.size_m, CameraMount(), jacobians=False).values[0]
    high = _slice(o.label, (b, w, hi + 0.3, hi + 0.5))  # same bearing, far above the object
    ok = _slice(o.label, (b, w, lo, hi))
    images = [ImageSlices(int(STAMPS[0]), (high, ok)), ImageSlices(int(STAMPS[-1] + 10**9), (ok,)), ImageSlices(0)]
    assert oracle_assignment(images, TRUTH, TRACK) == [(None, o.id), (None,), ()]


def test_truth_residual_chi2_is_the_normalized_squared_residual():
    objs = scene.OBJECTS
    poses = POSES[: len(objs)]
    positions, sizes = [o.position_m for o in objs], [o.size_m for o in objs]
    exact = predict_slices(poses, positions, sizes, CameraMount(), jacobians=False).values
    stddev = np.tile([0.006, 0.012, 0.01, 0.15], (len(objs), 1))
    assert np.allclose(truth_residual_chi2(exact, stddev, poses, positions, sizes, CameraMount()), 0.0, atol=1e-18)
    # k stddevs off in one component: chi2 = k^2; the bearing's residual is wrapped (2 pi apart is no error).
    off = exact.copy()
    off[:, 0] += 3.0 * stddev[:, 0] + 2.0 * np.pi
    off[:, 3] -= 2.0 * stddev[:, 3]
    chi2 = truth_residual_chi2(off, stddev, poses, positions, sizes, CameraMount())
    assert chi2 == pytest.approx(np.full(len(objs), 13.0), rel=1e-9)
    # A camera inside the object: no model prediction, never consistent.
    inside = truth_residual_chi2(exact[:1], stddev[:1], POSES[0], (*POSES[0, :2], 0.0), (0.5, 0.5), CameraMount())
    assert np.isinf(inside).all()


def test_residual_gate_is_the_chi_square_quantile_of_four_dof():
    # Chi-square with 4 dof has the survival function exp(-x/2) (1 + x/2).
    for p in (0.99, 0.999):
        x = OracleOptions(residual_gate_probability=p).residual_gate_chi2
        assert np.exp(-x / 2) * (1 + x / 2) == pytest.approx(1.0 - p, rel=1e-9)
