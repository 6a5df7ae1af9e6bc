"""The named scenarios of ``objslam sim``: a scene, a robot path and its odometry, per seed.

Everything is drawn from ``numpy.random.default_rng(seed)``, so a (name, seed, frames)
triple always gives the same scenario. ``frames`` only changes how finely the same
path is sampled: images stay at ``IMAGE_RATE_HZ``, so more frames mean a slower robot.

Objects are placed by rejection sampling where they are seen from the path (their
centre at most ``VIEW_RANGE_M`` from it) but never in its way: the robot keeps at least
``PLACEMENT_CLEARANCE_M`` from every surface while placing, and building a scenario
fails unless the final path keeps ``MIN_CLEARANCE_M`` from everything solid.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from objslam_common.cameras import DEFAULT_CAMERA, CameraModel, camera_info_fields
from objslam_common.catalog import Catalog, load_catalog
from objslam_common.mount import CameraMount
from objslam_tools.errors import UserError
from objslam_tools.ground_truth import Distractor, GroundTruth, GroundTruthObject, Room, Table
from objslam_tools.sim.motion import Drive, OdometryNoise, SmoothPath, spins_that_fit, wheel_odometry
from objslam_tools.sim.scene import Footprint, Lighting, Scene, distance_to_footprint, path_clearance_m

IMAGE_RATE_HZ = 5
ODOM_RATE_HZ = 50
IMAGE_OFFSET_NS = 10_000_000  # the first image 10 ms after the first odometry message
START_STAMP_NS = 1_715_679_000_000_000_000  # 2024-05-14T09:30:00Z
GROUND_TRUTH_FRAME = "world"
# Where `objslam sim --camera` mounts each preset camera: the omnidirectional one level on the
# rotation axis (the bundled bags); the forward-looking ones at the robot's front, pitched a
# little down as such cameras usually are, so that the mount's tilt is always exercised.
PRESET_MOUNTS = {
    "omni": CameraMount(),
    "pinhole": CameraMount(offset_x_m=0.1, pitch_rad=0.1),
    "fisheye": CameraMount(offset_x_m=0.1, pitch_rad=0.1),
}
# ... and how often the robot turns around on the spot on the way, so that a forward camera
# sees every object, from several places (motion.Drive).
PRESET_SPINS = {"omni": 0, "pinhole": 3, "fisheye": 3}
MIN_CLEARANCE_M = 0.4
PLACEMENT_CLEARANCE_M = 0.7
WALL_CLEARANCE_M = 0.8
VIEW_RANGE_M = 3.2
SIZE_SPREAD = 0.10  # instances differ from the nominal size by up to 10 %
TABLE_DIAMETER_M = (0.43, 0.47)
TABLE_HEIGHT_M = (0.72, 0.78)
_MAX_TRIES = 4000


class ScenarioError(UserError):
    """A scenario that cannot be built as asked."""


@dataclass(frozen=True)
class Scenario:
    """A complete simulated run: what is there, where the robot went, what odometry said."""

    name: str
    seed: int
    description: str
    scene: Scene
    camera: CameraModel
    mount: CameraMount
    path: SmoothPath
    image_stamps_ns: NDArray[np.int64]
    image_poses: NDArray[np.float64]  # (N, 3) true map_T_base at the image stamps
    odom_stamps_ns: NDArray[np.int64]
    true_poses: NDArray[np.float64]  # (M, 3) true map_T_base at the odometry stamps
    odom_poses: NDArray[np.float64]  # (M, 3) odom_T_base, starting at the identity
    odometry_noise: OdometryNoise
    min_clearance_m: float
    spins: int = 0  # turns on the spot along the path (motion.Drive)

    @property
    def frames(self) -> int:
        return len(self.image_stamps_ns)

    @property
    def mean_speed_mps(self) -> float:
        duration_s = (self.odom_stamps_ns[-1] - self.odom_stamps_ns[0]) * 1e-9
        return self.path.length_m / duration_s

    def simulation_info(self) -> dict[str, Any]:
        """The ``simulation`` section of ground_truth.yaml."""
        return {
            "scenario": self.name,
            "seed": self.seed,
            "frames": self.frames,
            "image_rate_hz": IMAGE_RATE_HZ,
            "odom_rate_hz": ODOM_RATE_HZ,
            "start_stamp_ns": int(self.odom_stamps_ns[0]),
            "path_length_m": round(self.path.length_m, 3),
            "mean_speed_mps": round(self.mean_speed_mps, 3),
            "min_clearance_m": round(self.min_clearance_m, 3),
            **({"spins": self.spins} if self.spins else {}),
            "initial_pose": [round(float(v), 6) for v in self.true_poses[0]],
            "odometry_noise": self.odometry_noise.as_dict(),
            "camera": {
                "distortion_model": camera_info_fields(self.camera)[0],
                "d": list(camera_info_fields(self.camera)[1]),
                "width": self.camera.width_px,
                "height": self.camera.height_px,
                "fx": self.camera.fx,
                "fy": self.camera.fy,
                "cx": self.camera.cx,
                "cy": self.camera.cy,
            },
        }

    def ground_truth(self) -> GroundTruth:
        return self.scene.ground_truth(self.mount, GROUND_TRUTH_FRAME, self.simulation_info())


# ---- scenario specifications ---------------------------------------------------------------


@dataclass(frozen=True)
class _Spec:
    description: str
    frames: int
    room_m: tuple[float, float]
    path: _LoopPath | _OpenPath
    objects: tuple[str, ...]  # labels, one per object
    twins: tuple[str, ...] = ()  # labels that come as pairs 0.7-1.0 m apart (in addition to ``objects``)
    distractors: Mapping[str, int] = field(default_factory=dict)


@dataclass(frozen=True)
class _LoopPath:
    """``laps`` laps of a rounded rectangle (superellipse) ``margin_m`` inside the walls, jittered per waypoint."""

    laps: float
    margin_m: tuple[float, float]
    per_lap: int = 10
    jitter_m: float = 0.15

    def build(self, rng: np.random.Generator, room: Room) -> SmoothPath:
        cx, cy = (room.x_min_m + room.x_max_m) / 2, (room.y_min_m + room.y_max_m) / 2
        a = (room.x_max_m - room.x_min_m) / 2 - self.margin_m[0]
        b = (room.y_max_m - room.y_min_m) / 2 - self.margin_m[1]
        direction = rng.choice([-1.0, 1.0])
        phase = rng.uniform(0, 2 * np.pi)
        steps = int(np.ceil(self.laps * self.per_lap))
        t = phase + direction * np.arange(steps + 1) * 2 * np.pi / self.per_lap
        c, s = np.cos(t), np.sin(t)
        r = 1.0 + rng.uniform(-1, 1, len(t)) * self.jitter_m / min(a, b)
        # Exponent 1/2 on |cos|, |sin|: the superellipse of degree 4, a rectangle with round corners.
        xy = np.column_stack(
            [cx + r * a * np.sign(c) * np.sqrt(np.abs(c)), cy + r * b * np.sign(s) * np.sqrt(np.abs(s))]
        )
        path = SmoothPath.through(xy)
        # The waypoints may over-run the last partial lap; cut the path at the asked number of laps.
        return path.truncated(path.length_m * self.laps * self.per_lap / steps)


@dataclass(frozen=True)
class _OpenPath:
    """Through waypoints at fractions of the room's extent, jittered, from the first to the last."""

    fractions: tuple[tuple[float, float], ...]
    jitter_m: float = 0.2

    def build(self, rng: np.random.Generator, room: Room) -> SmoothPath:
        f = np.asarray(self.fractions, dtype=float)
        x = room.x_min_m + f[:, 0] * (room.x_max_m - room.x_min_m)
        y = room.y_min_m + f[:, 1] * (room.y_max_m - room.y_min_m)
        return SmoothPath.through(np.column_stack([x, y]) + rng.uniform(-self.jitter_m, self.jitter_m, (len(f), 2)))


ALL = ("red", "green", "blue", "yellow", "cyan")

SPECS: dict[str, _Spec] = {
    "small": _Spec(
        "one of each class along an S-shaped drive through a small room, one poster",
        frames=100,
        room_m=(7.0, 5.0),
        path=_OpenPath(((0.16, 0.25), (0.36, 0.62), (0.58, 0.70), (0.78, 0.50), (0.86, 0.24))),
        objects=ALL,
        distractors={"poster": 1},
    ),
    "office": _Spec(
        "the standard: 12 objects of all five classes and 3 posters, 1.25 laps around an office",
        frames=400,
        room_m=(12.0, 9.0),
        path=_LoopPath(1.25, (2.0, 1.9)),
        objects=("red", "red", "red", "green", "green", "blue", "blue", "blue", "yellow", "yellow", "cyan", "cyan"),
        distractors={"poster": 3},
    ),
    "twins": _Spec(
        "pairs of same-class objects 0.7-1.0 m apart, plus three single objects",
        frames=300,
        room_m=(10.0, 8.0),
        path=_LoopPath(1.2, (1.9, 1.8)),
        objects=("yellow", "red", "green"),
        twins=("red", "blue", "green", "cyan"),
        distractors={"poster": 1},
    ),
    "clutter": _Spec(
        "8 objects among many distractors: posters, signs, patches on and near the floor",
        frames=300,
        room_m=(10.5, 8.0),
        path=_LoopPath(1.2, (2.0, 1.8), per_lap=9),
        objects=("red", "red", "green", "blue", "blue", "yellow", "cyan", "cyan"),
        distractors={"poster": 4, "sign": 3, "floor_patch": 6, "low_patch": 4},
    ),
    "loop": _Spec(
        "two laps of a large room with revisits, 12 objects and 2 posters",
        frames=900,
        room_m=(14.0, 11.0),
        path=_LoopPath(2.05, (2.1, 2.0)),
        objects=("red", "red", "green", "green", "green", "blue", "blue", "yellow", "yellow", "cyan", "cyan", "red"),
        distractors={"poster": 2},
    ),
}
SCENARIO_NAMES = tuple(SPECS)


# ---- placement -------------------------------------------------------------------------------


class _Placer:
    """Rejection sampling of things on the floor, with the path and each other kept clear."""

    def __init__(self, rng: np.random.Generator, room: Room, path_xy: NDArray[np.float64]) -> None:
        self.rng = rng
        self.room = room
        self.path_xy = path_xy
        self.placed: list[Footprint] = []

    def _fits(self, fp: Footprint, gap_m: float, partner: Footprint | None) -> bool:
        r = self.room
        margin = fp.radius_m + 0.25
        for p in (fp.start_xy, fp.end_xy):
            if not (
                r.x_min_m + margin <= p[0] <= r.x_max_m - margin and r.y_min_m + margin <= p[1] <= r.y_max_m - margin
            ):
                return False
        to_path = float(np.min(distance_to_footprint(self.path_xy, fp)))
        if to_path < PLACEMENT_CLEARANCE_M or to_path + fp.radius_m > VIEW_RANGE_M:
            return False
        for other in self.placed:
            along = np.linspace(0.0, 1.0, 5)[:, None]
            points = np.asarray(other.start_xy) + along * (np.asarray(other.end_xy) - np.asarray(other.start_xy))
            gap = float(np.min(distance_to_footprint(points, fp))) - other.radius_m
            if gap < (0.05 if other is partner else gap_m):
                return False
        return True

    def place_disc(
        self, radius_m: float, name: str, gap_m: float = 0.6, partner: Footprint | None = None
    ) -> NDArray[np.float64]:
        """Centre of a free disc; with a ``partner`` disc, 0.7-1.0 m from its centre (twins)."""
        r = self.room
        for _ in range(_MAX_TRIES):
            if partner is None:
                xy = np.array([self.rng.uniform(r.x_min_m, r.x_max_m), self.rng.uniform(r.y_min_m, r.y_max_m)])
            else:
                angle = self.rng.uniform(0, 2 * np.pi)
                xy = np.asarray(partner.start_xy) + self.rng.uniform(0.7, 1.0) * np.array(
                    [np.cos(angle), np.sin(angle)]
                )
            fp = Footprint(name, (float(xy[0]), float(xy[1])), (float(xy[0]), float(xy[1])), radius_m)
            if self._fits(fp, gap_m, partner):
                self.placed.append(fp)
                return xy
        raise ScenarioError(f"cannot place {name} clear of the path and the other objects")

    def place_segment(self, half_width_m: float, radius_m: float, name: str) -> tuple[NDArray[np.float64], float]:
        """Centre and yaw of a free straight board (a sign) of that half width."""
        r = self.room
        for _ in range(_MAX_TRIES):
            xy = np.array([self.rng.uniform(r.x_min_m, r.x_max_m), self.rng.uniform(r.y_min_m, r.y_max_m)])
            yaw = self.rng.uniform(-np.pi, np.pi)
            half = half_width_m * np.array([-np.sin(yaw), np.cos(yaw)])
            fp = Footprint(name, tuple(xy - half), tuple(xy + half), radius_m)  # type: ignore[arg-type]
            if self._fits(fp, 0.5, None):
                self.placed.append(fp)
                return xy, float(yaw)
        raise ScenarioError(f"cannot place {name} clear of the path and the other objects")


def _instance_size(rng: np.random.Generator, nominal: float) -> float:
    return float(nominal * (1.0 + rng.uniform(-SIZE_SPREAD, SIZE_SPREAD)))


def _place_objects(rng: np.random.Generator, placer: _Placer, spec: _Spec, catalog: Catalog):
    objects: list[GroundTruthObject] = []
    tables: list[Table] = []
    groups = [(label,) for label in spec.objects] + [(label, label) for label in spec.twins]
    order = rng.permutation(len(groups))
    for gi in order:
        partner: Footprint | None = None
        for label in groups[gi]:
            cls = catalog[label]
            diameter = _instance_size(rng, cls.diameter_m)
            height = _instance_size(rng, cls.height_m)
            oid = len(objects)
            if cls.on_floor:
                footprint_r, z_base = diameter / 2, 0.0
            else:
                table_d = rng.uniform(*TABLE_DIAMETER_M)
                footprint_r, z_base = max(table_d, diameter) / 2, float(rng.uniform(*TABLE_HEIGHT_M))
            xy = placer.place_disc(footprint_r, f"object {oid} ({label})", partner=partner)
            if not cls.on_floor:
                tables.append(Table(len(tables), (float(xy[0]), float(xy[1]), 0.0), (footprint_r * 2, z_base), oid))
            objects.append(GroundTruthObject(oid, label, (float(xy[0]), float(xy[1]), z_base), (diameter, height)))
            partner = placer.placed[-1]
    return tuple(objects), tuple(tables)


def _class_color(rng: np.random.Generator, catalog: Catalog, label: str) -> tuple[int, int, int]:
    rgb = np.asarray(catalog[label].color_rgb) + rng.integers(-12, 13, 3)
    return tuple(int(v) for v in np.clip(rgb, 0, 255))  # type: ignore[return-value]


def _wall_spot(rng: np.random.Generator, room: Room, width_m: float, taken: list[tuple[int, float, float]]):
    """(center xy, inward yaw) of a free spot for something of that width on a wall."""
    walls = [  # start, direction along the wall, length, inward yaw
        (np.array([room.x_min_m, room.y_min_m]), np.array([1.0, 0.0]), room.x_max_m - room.x_min_m, np.pi / 2),
        (np.array([room.x_max_m, room.y_min_m]), np.array([0.0, 1.0]), room.y_max_m - room.y_min_m, np.pi),
        (np.array([room.x_max_m, room.y_max_m]), np.array([-1.0, 0.0]), room.x_max_m - room.x_min_m, -np.pi / 2),
        (np.array([room.x_min_m, room.y_max_m]), np.array([0.0, -1.0]), room.y_max_m - room.y_min_m, 0.0),
    ]
    lengths = np.array([w[2] for w in walls])
    for _ in range(_MAX_TRIES):
        k = int(rng.choice(4, p=lengths / lengths.sum()))
        start, along, length, yaw = walls[k]
        pos = rng.uniform(0.6 + width_m / 2, length - 0.6 - width_m / 2)
        if all(kk != k or abs(pos - p) > (width_m + w) / 2 + 0.3 for kk, p, w in taken):
            taken.append((k, pos, width_m))
            inward = np.array([np.cos(yaw), np.sin(yaw)])
            return start + pos * along + 0.005 * inward, yaw
    raise ScenarioError("no free wall space left for another poster")


def _place_distractors(rng: np.random.Generator, placer: _Placer, spec: _Spec, catalog: Catalog, room: Room):
    out: list[Distractor] = []
    taken: list[tuple[int, float, float]] = []
    labels = catalog.labels
    for kind, count in spec.distractors.items():
        for _ in range(count):
            label = str(rng.choice(labels))
            rgb = _class_color(rng, catalog, label)
            if kind == "poster":
                size = (rng.uniform(0.5, 0.9), rng.uniform(0.4, 0.7))
                xy, yaw = _wall_spot(rng, room, size[0], taken)
                center = (xy[0], xy[1], rng.uniform(0.95, 1.2))
            elif kind == "low_patch":
                size = (rng.uniform(0.08, 0.25), rng.uniform(0.05, 0.15))
                xy, yaw = _wall_spot(rng, room, size[0], taken)
                center = (xy[0], xy[1], size[1] / 2 + rng.uniform(0.0, 0.2))
            elif kind == "sign":
                size = (rng.uniform(0.3, 0.45), rng.uniform(0.25, 0.35))
                xy, yaw = placer.place_segment(size[0] / 2, 0.03, f"sign {len(out)}")
                center = (xy[0], xy[1], rng.uniform(0.6, 0.9))
            elif kind == "floor_patch":
                size = (rng.uniform(0.08, 0.25), rng.uniform(0.08, 0.2))
                xy = placer.place_disc(float(np.hypot(*size)) / 2, f"floor patch {len(out)}", gap_m=0.2)
                yaw = rng.uniform(-np.pi, np.pi)
                center = (xy[0], xy[1], 0.002)
            else:
                raise ScenarioError(f"unknown distractor kind {kind!r}")
            out.append(
                Distractor(
                    id=len(out),
                    kind=kind,
                    label=label,
                    color_rgb=rgb,
                    center_m=tuple(float(v) for v in center),  # type: ignore[arg-type]
                    size_m=(float(size[0]), float(size[1])),
                    yaw_rad=float(yaw),
                )
            )
    return tuple(out)


# ---- the whole scenario ---------------------------------------------------------------------


def build_scenario(
    name: str,
    seed: int = 0,
    frames: int | None = None,
    *,
    catalog: Catalog | None = None,
    camera: CameraModel = DEFAULT_CAMERA,
    mount: CameraMount | None = None,
    odometry_noise: OdometryNoise | None = None,
    spins: int = 0,
) -> Scenario:
    """The scenario ``name`` for ``seed``, with ``frames`` images (default: the scenario's own count)."""
    spec = SPECS.get(name)
    if spec is None:
        raise ScenarioError(f"unknown scenario {name!r} (known: {', '.join(SCENARIO_NAMES)})")
    frames = spec.frames if frames is None else int(frames)
    if frames < 2:
        raise ScenarioError(f"--frames must be at least 2, got {frames}")
    if seed < 0:
        raise ScenarioError(f"--seed must be >= 0, got {seed}")
    catalog = catalog or load_catalog()
    mount = mount or CameraMount()
    noise = odometry_noise or OdometryNoise()
    missing = sorted({*spec.objects, *spec.twins} - set(catalog.labels))
    if missing:
        raise ScenarioError(f"scenario {name!r} needs classes missing from the catalog: {', '.join(missing)}")

    rng = np.random.default_rng(seed)
    room = Room(0.0, spec.room_m[0], 0.0, spec.room_m[1])
    path = spec.path.build(rng, room)
    placer = _Placer(rng, room, path.xy_m)
    objects, tables = _place_objects(rng, placer, spec, catalog)
    distractors = _place_distractors(rng, placer, spec, catalog, room)
    lighting = Lighting(azimuth_rad=float(rng.uniform(-np.pi, np.pi)), elevation_rad=float(rng.uniform(0.7, 1.05)))
    scene = Scene.with_catalog(room, objects, catalog, tables=tables, distractors=distractors, lighting=lighting)

    clearance, closest = path_clearance_m(scene, path.xy_m)
    wall_clearance = min(
        np.min(path.xy_m[:, 0] - room.x_min_m),
        np.min(room.x_max_m - path.xy_m[:, 0]),
        np.min(path.xy_m[:, 1] - room.y_min_m),
        np.min(room.y_max_m - path.xy_m[:, 1]),
    )
    if clearance < MIN_CLEARANCE_M or wall_clearance < WALL_CLEARANCE_M:
        raise ScenarioError(f"scenario {name!r} seed {seed}: the path passes {clearance:.2f} m from {closest}")

    image_t_ns = IMAGE_OFFSET_NS + np.arange(frames, dtype=np.int64) * (1_000_000_000 // IMAGE_RATE_HZ)
    odom_period_ns = 1_000_000_000 // ODOM_RATE_HZ
    odom_count = int(np.ceil(image_t_ns[-1] / odom_period_ns)) + 1
    odom_t_ns = np.arange(odom_count, dtype=np.int64) * odom_period_ns
    if spins < 0:
        raise ScenarioError(f"--spins must be >= 0, got {spins}")
    spins = spins_that_fit(odom_t_ns[-1] * 1e-9, spins)
    drive = Drive(path, odom_t_ns[-1] * 1e-9, spins)
    true_poses = drive.pose_at(odom_t_ns * 1e-9)
    image_poses = drive.pose_at(image_t_ns * 1e-9)
    odom_poses = wheel_odometry(true_poses, noise, np.random.default_rng([seed, 1]))

    return Scenario(
        name=name,
        seed=seed,
        description=spec.description,
        scene=scene,
        camera=camera,
        mount=mount,
        path=path,
        image_stamps_ns=START_STAMP_NS + image_t_ns,
        image_poses=image_poses,
        odom_stamps_ns=START_STAMP_NS + odom_t_ns,
        true_poses=true_poses,
        odom_poses=odom_poses,
        odometry_noise=noise,
        min_clearance_m=float(min(clearance, wall_clearance)),
        spins=spins,
    )


def render_rng(scenario: Scenario) -> np.random.Generator:
    """The generator for image noise, independent of how the scene was drawn."""
    return np.random.default_rng([scenario.seed, 2])


def describe_scenarios() -> dict[str, str]:
    return {name: f"{spec.description} (~{spec.frames} frames)" for name, spec in SPECS.items()}
