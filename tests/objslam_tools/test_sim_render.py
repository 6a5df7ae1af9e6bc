"""The renderer against the camera model: things appear where the model projects them, in their colour.

Visibility is decided here independently of the renderer: a point counts as visible when
the straight segment from the camera to it stays clear of every other solid cylinder
(with a margin) and it projects well inside the image circle.
"""

from __future__ import annotations

import colorsys

import cv2
import numpy as np
import pytest

from objslam_common.cameras.unified import DEFAULT_CAMERA
from objslam_common.catalog import load_catalog
from objslam_common.mount import CameraMount
from objslam_tools.ground_truth import Distractor, GroundTruthObject, Room, Table
from objslam_tools.sim import Renderer, Scene, build_scenario, render_frame
from objslam_tools.sim.scene import SIGN_POST_RADIUS_M

CATALOG = load_catalog()
MOUNT = CameraMount()
MAX_RADIUS_PX = 300.0  # well inside the 319 px image circle


def hue_deg(rgb) -> float:
    r, g, b = (float(c) / 255.0 for c in rgb)
    return 360.0 * colorsys.rgb_to_hsv(r, g, b)[0]


def assert_colour(image: np.ndarray, uv: tuple[float, float], expected_rgb, what: str) -> None:
    u, v = round(uv[0]), round(uv[1])
    pixel = image[v, u].astype(float)
    diff = abs(hue_deg(pixel) - hue_deg(expected_rgb))
    assert min(diff, 360.0 - diff) < 12.0, f"{what} at pixel ({u}, {v}) is {pixel}, expected hue of {expected_rgb}"
    sat = colorsys.rgb_to_hsv(*(pixel / 255.0))[1]
    assert sat > 0.6, f"{what} at pixel ({u}, {v}) is {pixel}: not saturated like {expected_rgb}"


def solid_cylinders(scene: Scene) -> list[tuple[str, np.ndarray, float, float, float]]:
    """(name, xy, radius, z_base, z_top) of everything round and solid in the scene."""
    out = [
        (f"object {o.id}", np.array(o.position_m[:2]), o.radius_m, o.position_m[2], o.z_top_m) for o in scene.objects
    ]
    out += [(f"table {t.id}", np.array(t.position_m[:2]), t.radius_m, 0.0, t.size_m[1]) for t in scene.tables]
    for d in scene.distractors:
        if d.kind == "sign":  # the post, and the board as a fat cylinder around it (conservative)
            bottom = d.center_m[2] - d.size_m[1] / 2
            out.append((f"post {d.id}", np.array(d.center_m[:2]), SIGN_POST_RADIUS_M, 0.0, bottom))
            out.append((f"sign {d.id}", np.array(d.center_m[:2]), d.size_m[0] / 2, bottom, bottom + d.size_m[1]))
    return out


def segment_is_clear(camera_xyz: np.ndarray, point_xyz: np.ndarray, cylinders, skip: str, margin: float = 0.03) -> bool:
    s = np.linspace(0.0, 1.0, 400)[:, None]
    pts = camera_xyz + s * (point_xyz - camera_xyz)
    for name, xy, radius, z0, z1 in cylinders:
        if name == skip:
            continue
        inside = (
            (np.hypot(*(pts[:, :2] - xy).T) < radius + margin) & (pts[:, 2] > z0 - margin) & (pts[:, 2] < z1 + margin)
        )
        if inside.any():
            return False
    return True


def project(pose: np.ndarray, point_xyz: np.ndarray) -> tuple[float, float, float]:
    """Pixel (u, v) of a world point seen from robot pose, and its radius from the image centre."""
    az, el, _rng = MOUNT.direction_to(pose, point_xyz)
    u, v = DEFAULT_CAMERA.project(az[0], el[0])
    return float(u), float(v), float(np.hypot(u - DEFAULT_CAMERA.cx, v - DEFAULT_CAMERA.cy))


def camera_xyz(pose: np.ndarray) -> np.ndarray:
    cam = MOUNT.camera_pose(pose)
    return np.array([cam[0], cam[1], MOUNT.height_m])


@pytest.fixture(scope="module")
def office():
    return build_scenario("office", seed=2)


@pytest.fixture(scope="module")
def clutter():
    return build_scenario("clutter", seed=0)


@pytest.mark.parametrize("frame", [30, 170, 330])
def test_visible_objects_show_their_colour_where_the_model_projects_them(office, frame: int) -> None:
    pose = office.image_poses[frame]
    image = render_frame(office.scene, pose, rng=np.random.default_rng(frame))
    cam = camera_xyz(pose)
    cylinders = solid_cylinders(office.scene)
    checked = 0
    for obj in office.scene.objects:
        centre = np.array(obj.position_m[:2])
        toward = (cam[:2] - centre) / np.linalg.norm(cam[:2] - centre)
        # The centre of the visible side, at mid-height.
        point = np.r_[centre + obj.radius_m * toward, obj.position_m[2] + obj.size_m[1] / 2]
        u, v, radius = project(pose, point)
        if not radius < MAX_RADIUS_PX or not segment_is_clear(cam, point, cylinders, skip=f"object {obj.id}"):
            continue
        assert_colour(image, (u, v), CATALOG[obj.label].color_rgb, f"object {obj.id} ({obj.label})")
        checked += 1
    assert checked >= 5, "too few visible objects: the test would prove nothing"


@pytest.mark.parametrize("frame", [40, 200])
def test_distractors_appear_where_placed(clutter, frame: int) -> None:
    pose = clutter.image_poses[frame]
    image = render_frame(clutter.scene, pose, rng=np.random.default_rng(frame))
    cam = camera_xyz(pose)
    cylinders = solid_cylinders(clutter.scene)
    checked = 0
    for d in clutter.scene.distractors:
        u, v, radius = project(pose, np.asarray(d.center_m))
        if not radius < MAX_RADIUS_PX:
            continue
        # Only where the whole rectangle is in view and the centre lies well inside its image.
        corners = np.array([project(pose, c)[:2] for c in d.corners_m()], dtype=np.float32)
        if not np.all(np.isfinite(corners)) or cv2.pointPolygonTest(corners, (u, v), True) < 2.0:
            continue
        if not segment_is_clear(cam, np.asarray(d.center_m), cylinders, skip=f"sign {d.id}"):
            continue
        assert_colour(image, (u, v), d.color_rgb, f"distractor {d.id} ({d.kind}, {d.label})")
        checked += 1
    assert checked >= 3, "too few visible distractors: the test would prove nothing"


def hand_scene(**kwargs) -> Scene:
    objects = (
        GroundTruthObject(0, "red", (2.0, 0.0, 0.0), (0.3, 0.6)),  # 2 m ahead of the robot
        GroundTruthObject(1, "blue", (4.0, 0.0, 0.0), (0.2, 0.4)),  # right behind it, and lower
        GroundTruthObject(2, "cyan", (0.0, 2.0, 0.75), (0.15, 0.25)),  # on a table to the left
    )
    tables = (Table(0, (0.0, 2.0, 0.0), (0.45, 0.75), 2),)
    distractors = (
        Distractor(0, "poster", "green", (30, 160, 60), (-2.995, 0.0, 1.0), (0.8, 0.6), 0.0),  # behind, on the wall
        Distractor(1, "floor_patch", "yellow", (220, 200, 30), (0.0, -1.5, 0.002), (0.3, 0.3), 0.0),  # right
    )
    return Scene.with_catalog(
        Room(-3.0, 6.0, -3.0, 4.0), objects, CATALOG, tables=tables, distractors=distractors, **kwargs
    )


def test_nearest_hit_wins_occlusion_and_scene_layout() -> None:
    scene = hand_scene()
    pose = np.zeros(3)
    rendering = Renderer(DEFAULT_CAMERA, MOUNT).render(scene, pose)
    image = rendering.image_rgb
    # The blue cylinder stands right behind the red one: its centre shows red.
    u, v, _ = project(pose, np.array([3.9, 0.0, 0.2]))
    assert_colour(image, (u, v), CATALOG["red"].color_rgb, "occluded blue object")
    assert rendering.mask("object", 1).sum() == 0
    # Forward is +u, left is up (-v) in the image (docs/design.md camera model).
    u, v, _ = project(pose, np.array([1.85, 0.0, 0.3]))
    assert u > DEFAULT_CAMERA.cx + 100 and abs(v - DEFAULT_CAMERA.cy) < 1
    assert_colour(image, (u, v), CATALOG["red"].color_rgb, "red object")
    u, v, _ = project(pose, np.array([0.0, 2.0 - 0.075, 0.875]))
    assert v < DEFAULT_CAMERA.cy - 100
    assert_colour(image, (u, v), CATALOG["cyan"].color_rgb, "cyan object on its table")
    # The table hides the cyan object's base from a camera below the table top.
    u, v, _ = project(pose, np.array([0.0, 2.0 - 0.075, 0.76]))
    assert rendering.element[round(v), round(u)] == rendering.elements.index(("table", 0))
    u, v, _ = project(pose, np.array([-2.995, 0.0, 1.0]))
    assert_colour(image, (u, v), (30, 160, 60), "poster behind the robot")
    u, v, _ = project(pose, np.array([0.0, -1.5, 0.002]))
    assert_colour(image, (u, v), (220, 200, 30), "floor patch to the right")


def test_pixels_outside_the_image_circle_are_black_and_the_room_closes_every_ray() -> None:
    rendering = Renderer(DEFAULT_CAMERA, MOUNT).render(hand_scene(), np.array([0.5, 0.2, 1.0]))
    yy, xx = np.mgrid[0:640, 0:640]
    outside = np.hypot(xx - 320, yy - 320) > 320
    assert np.all(rendering.image_rgb[outside] == 0)
    assert np.all(rendering.element[outside] == -1)
    inside = np.hypot(xx - 320, yy - 320) < 315
    assert np.all(rendering.element[inside] >= 0)
    assert np.all(rendering.image_rgb[inside].sum(axis=-1) > 0)
    # Straight down is the floor.
    assert rendering.elements[rendering.element[320, 320]] == ("floor", 0)


def test_shading_varies_around_the_albedo() -> None:
    scene = hand_scene()
    rendering = Renderer(DEFAULT_CAMERA, MOUNT).render(scene, np.zeros(3))
    # Red's albedo is (200, 30, 30): its red channel is the brightness of the lit side.
    red = rendering.image_rgb[rendering.mask("object", 0)][:, 0].astype(float)
    assert len(red) > 200
    assert red.max() - red.min() > 20, "a cylinder side must be shaded by its normal"
    assert 0.7 * 200 < np.median(red) < 1.1 * 200


def test_noise_and_determinism() -> None:
    scene = hand_scene()
    pose = np.array([0.3, -0.2, 0.4])
    clean = render_frame(scene, pose).astype(float)
    assert np.array_equal(clean, render_frame(scene, pose).astype(float))
    a = render_frame(scene, pose, rng=np.random.default_rng(5)).astype(float)
    b = render_frame(scene, pose, rng=np.random.default_rng(5)).astype(float)
    assert np.array_equal(a, b)
    inside = clean.sum(axis=-1) > 0
    residual = (a - clean)[inside]
    residual -= residual.mean(axis=0)  # exposure jitter is a common gain
    assert 1.5 < residual.std() < 3.5  # ~2 grey levels of pixel noise, plus the gain's spread
