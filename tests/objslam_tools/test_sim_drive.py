"""Turns on the spot along a simulated drive (``objslam sim --spins``): where they stand, that
they turn once around without moving, and that a drive without them is the plain path."""

from __future__ import annotations

import numpy as np
import pytest

from objslam_common.geometry import wrap_angle
from objslam_tools.sim.motion import SPIN_S, Drive, PathError, SmoothPath, SpeedProfile, spins_that_fit
from objslam_tools.sim.scenarios import build_scenario

PATH = SmoothPath.through(np.array([[0.0, 0.0], [2.0, 1.0], [4.0, 0.0], [6.0, 1.0]]))
DURATION_S = 60.0


def test_a_drive_without_spins_is_the_path_under_one_speed_profile():
    t = np.linspace(0.0, DURATION_S, 301)
    profile = SpeedProfile.for_path(PATH.length_m, DURATION_S)
    np.testing.assert_array_equal(Drive(PATH, DURATION_S).pose_at(t), PATH.pose_at(profile.distance_at(t)))


@pytest.mark.parametrize("spins", [1, 3])
def test_each_spin_turns_once_around_on_the_spot_then_the_drive_goes_on(spins):
    drive = Drive(PATH, DURATION_S, spins)
    leg_s = (DURATION_S - spins * SPIN_S) / spins
    for k in range(spins):
        start = k * (SPIN_S + leg_s)
        t = start + np.linspace(0.0, SPIN_S, 61)
        poses = drive.pose_at(t)
        np.testing.assert_allclose(poses[:, :2], np.repeat(PATH.pose_at(k * PATH.length_m / spins)[None, :2], 61, 0))
        turned = np.unwrap(poses[:, 2])
        assert turned[-1] - turned[0] == pytest.approx(2.0 * np.pi, abs=1e-9)
        assert np.all(np.diff(turned) >= -1e-12)  # counter-clockwise all the way
        assert np.max(np.diff(turned) / np.diff(t)) <= 1.5 + 1e-6  # rad/s
    end = drive.pose_at(np.array([DURATION_S]))[0]
    np.testing.assert_allclose(end[:2], PATH.xy_m[-1], atol=1e-9)
    assert wrap_angle(end[2] - PATH.heading_rad[-1]) == pytest.approx(0.0, abs=1e-9)


def test_spins_take_at_most_half_of_the_time():
    assert spins_that_fit(10.0, 3) == 0
    assert spins_that_fit(40.0, 3) == 3
    assert spins_that_fit(20.0, 3) == int(10.0 // SPIN_S)
    with pytest.raises(PathError):
        spins_that_fit(10.0, -1)


def test_a_scenario_records_its_spins_and_keeps_its_places():
    plain = build_scenario("office", seed=1, frames=120)
    spun = build_scenario("office", seed=1, frames=120, spins=1)
    assert spun.spins == 1 and spun.simulation_info()["spins"] == 1 and "spins" not in plain.simulation_info()
    assert spun.scene == plain.scene  # the same room and objects: only the motion differs
    assert not np.allclose(spun.image_poses, plain.image_poses)
