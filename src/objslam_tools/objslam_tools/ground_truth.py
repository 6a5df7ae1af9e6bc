"""What a simulated bag really holds: ``ground_truth.yaml`` beside ``metadata.yaml``.

Everything is in the frame of ``/ground_truth/odom`` (``frame_id``, default ``world``),
which is *not* the ``odom`` frame of ``/odom``: the robot starts at a non-identity pose
there. Units are metres and radians. The file::

    frame_id: world
    camera_mount: {height_m: 0.5, offset_x_m: 0.0, offset_y_m: 0.0, yaw_rad: 0.0}  # + roll_rad, pitch_rad if tilted
    room: {x: [0.0, 12.0], y: [0.0, 9.0], wall_height_m: 3.0}      # optional
    objects:      # the real objects, what a map should contain
      - {id: 0, label: red, position: [x, y, z_base], size: [diameter, height]}
    tables:       # grey cylinders under elevated objects (not objects of the catalog)
      - {id: 0, position: [x, y, 0.0], size: [diameter, height], object_id: 3}
    distractors:  # things of class colours that are not objects
      - {id: 0, kind: poster, label: red, color_rgb: [r, g, b], center: [x, y, z], size: [width, height], yaw: rad}
    simulation: {...}  # free-form: scenario, seed, rates, odometry noise figures

Distractor rectangles: ``poster`` (on a wall), ``sign`` (a free-standing board on a thin
grey post from the floor to its lower edge) and ``low_patch`` (a small patch on a wall
near the floor) are vertical: ``yaw`` is the direction their face looks at, ``width``
runs horizontally across it and ``height`` vertically. ``floor_patch`` lies on the
floor: ``width`` runs along ``yaw`` and ``height`` across it.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from numpy.typing import NDArray

from objslam_common.mount import CameraMount
from objslam_tools.errors import UserError

GROUND_TRUTH_FILE = "ground_truth.yaml"
VERTICAL_KINDS = ("poster", "sign", "low_patch")
HORIZONTAL_KINDS = ("floor_patch",)
DISTRACTOR_KINDS = VERTICAL_KINDS + HORIZONTAL_KINDS


@dataclass(frozen=True)
class GroundTruthObject:
    """A real object: an upright cylinder of a catalog class."""

    id: int
    label: str
    position_m: tuple[float, float, float]  # x, y, z_base
    size_m: tuple[float, float]  # diameter, height

    @property
    def radius_m(self) -> float:
        return self.size_m[0] / 2.0

    @property
    def z_top_m(self) -> float:
        return self.position_m[2] + self.size_m[1]


@dataclass(frozen=True)
class Table:
    """A grey cylindrical table standing on the floor (its top carries an elevated object)."""

    id: int
    position_m: tuple[float, float, float]  # x, y, z_base (0: on the floor)
    size_m: tuple[float, float]  # diameter, height
    object_id: int | None = None

    @property
    def radius_m(self) -> float:
        return self.size_m[0] / 2.0


@dataclass(frozen=True)
class Distractor:
    """A flat rectangle in a class colour that is not an object (module docstring: geometry)."""

    id: int
    kind: str
    label: str
    color_rgb: tuple[int, int, int]
    center_m: tuple[float, float, float]
    size_m: tuple[float, float]  # width, height
    yaw_rad: float

    @property
    def is_vertical(self) -> bool:
        return self.kind in VERTICAL_KINDS

    def axes(self) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """Unit vectors (width axis, height axis, face normal) in the world frame."""
        c, s = np.cos(self.yaw_rad), np.sin(self.yaw_rad)
        if self.is_vertical:
            return np.array([-s, c, 0.0]), np.array([0.0, 0.0, 1.0]), np.array([c, s, 0.0])
        return np.array([c, s, 0.0]), np.array([-s, c, 0.0]), np.array([0.0, 0.0, 1.0])

    def corners_m(self) -> NDArray[np.float64]:
        """(4, 3) corners, counter-clockwise seen from the face normal, for projecting into images."""
        w_axis, h_axis, _n = self.axes()
        centre = np.asarray(self.center_m, dtype=float)
        hw, hh = self.size_m[0] / 2.0, self.size_m[1] / 2.0
        signs = ((-1, -1), (1, -1), (1, 1), (-1, 1))
        return np.array([centre + sw * hw * w_axis + sh * hh * h_axis for sw, sh in signs])


@dataclass(frozen=True)
class Room:
    """An axis-aligned rectangular room (walls, floor at z = 0, ceiling)."""

    x_min_m: float
    x_max_m: float
    y_min_m: float
    y_max_m: float
    wall_height_m: float = 3.0


@dataclass(frozen=True)
class GroundTruth:
    objects: tuple[GroundTruthObject, ...]
    tables: tuple[Table, ...] = ()
    distractors: tuple[Distractor, ...] = ()
    mount: CameraMount = field(default_factory=CameraMount)
    room: Room | None = None
    frame_id: str = "world"
    simulation: Mapping[str, Any] = field(default_factory=dict)


def _floats(value: Any, n: int, name: str) -> tuple[float, ...]:
    if not isinstance(value, (list, tuple)) or len(value) != n:
        raise ValueError(f"'{name}' must be a list of {n} numbers, got {value!r}")
    out = tuple(float(v) for v in value)
    if not all(np.isfinite(out)):
        raise ValueError(f"'{name}' must be finite, got {value!r}")
    return out


def _positive_size(value: Any, name: str) -> tuple[float, float]:
    size = _floats(value, 2, name)
    if min(size) <= 0.0:
        raise ValueError(f"'{name}' must be positive, got {list(size)}")
    return size  # type: ignore[return-value]


def _object(d: Mapping[str, Any], index: int) -> GroundTruthObject:
    return GroundTruthObject(
        id=int(d.get("id", index)),
        label=str(d["label"]),
        position_m=_floats(d["position"], 3, "position"),  # type: ignore[arg-type]
        size_m=_positive_size(d["size"], "size"),
    )


def _table(d: Mapping[str, Any], index: int) -> Table:
    position = d["position"]
    if isinstance(position, (list, tuple)) and len(position) == 2:
        position = [*position, 0.0]
    object_id = d.get("object_id")
    return Table(
        id=int(d.get("id", index)),
        position_m=_floats(position, 3, "position"),  # type: ignore[arg-type]
        size_m=_positive_size(d["size"], "size"),
        object_id=None if object_id is None else int(object_id),
    )


def _distractor(d: Mapping[str, Any], index: int) -> Distractor:
    kind = str(d["kind"])
    if kind not in DISTRACTOR_KINDS:
        raise ValueError(f"unknown distractor kind {kind!r} (known: {', '.join(DISTRACTOR_KINDS)})")
    rgb = tuple(int(v) for v in _floats(d["color_rgb"], 3, "color_rgb"))
    if not all(0 <= v <= 255 for v in rgb):
        raise ValueError(f"'color_rgb' must be three values in 0..255, got {list(rgb)}")
    return Distractor(
        id=int(d.get("id", index)),
        kind=kind,
        label=str(d["label"]),
        color_rgb=rgb,  # type: ignore[arg-type]
        center_m=_floats(d["center"], 3, "center"),  # type: ignore[arg-type]
        size_m=_positive_size(d["size"], "size"),
        yaw_rad=float(d.get("yaw", 0.0)),
    )


def _mapping(d: Any, name: str) -> Mapping[str, Any]:
    if not isinstance(d, dict):
        raise ValueError(f"'{name}' must be a mapping, got {d!r}")
    return d


def _mount(d: Mapping[str, Any] | None) -> CameraMount:
    if d is None:
        return CameraMount()
    d = _mapping(d, "camera_mount")
    known = {"height_m", "offset_x_m", "offset_y_m", "yaw_rad", "roll_rad", "pitch_rad"}
    unknown = sorted(set(d) - known)
    if unknown:
        raise ValueError(f"camera_mount: unknown key {unknown[0]!r}")
    return CameraMount(**{k: float(v) for k, v in d.items()})


def _room(d: Mapping[str, Any] | None) -> Room | None:
    if d is None:
        return None
    d = _mapping(d, "room")
    x = _floats(d["x"], 2, "room.x")
    y = _floats(d["y"], 2, "room.y")
    if x[0] >= x[1] or y[0] >= y[1]:
        raise ValueError(f"room bounds must be increasing, got x={list(x)}, y={list(y)}")
    return Room(x[0], x[1], y[0], y[1], float(d.get("wall_height_m", 3.0)))


def _items(data: Mapping[str, Any], key: str) -> list[Mapping[str, Any]]:
    items = data.get(key) or []
    if not isinstance(items, list) or not all(isinstance(i, dict) for i in items):
        raise ValueError(f"'{key}' must be a list of mappings")
    return items


def ground_truth_from_dict(data: Any) -> GroundTruth:
    """Parse the YAML mapping; ValueError/KeyError/TypeError on malformed content."""
    if not isinstance(data, dict) or "objects" not in data:
        raise ValueError("expected a mapping with 'objects'")
    simulation = data.get("simulation") or {}
    if not isinstance(simulation, dict):
        raise ValueError("'simulation' must be a mapping")
    return GroundTruth(
        objects=tuple(_object(d, i) for i, d in enumerate(_items(data, "objects"))),
        tables=tuple(_table(d, i) for i, d in enumerate(_items(data, "tables"))),
        distractors=tuple(_distractor(d, i) for i, d in enumerate(_items(data, "distractors"))),
        mount=_mount(data.get("camera_mount")),
        room=_room(data.get("room")),
        frame_id=str(data.get("frame_id", "world")),
        simulation=simulation,
    )


def ground_truth_to_dict(gt: GroundTruth) -> dict[str, Any]:
    """YAML-safe mapping in the file layout of the module docstring."""

    def fl(values: Any) -> list[float]:
        return [round(float(v), 6) for v in values]

    data: dict[str, Any] = {
        "frame_id": gt.frame_id,
        "camera_mount": {
            "height_m": float(gt.mount.height_m),
            "offset_x_m": float(gt.mount.offset_x_m),
            "offset_y_m": float(gt.mount.offset_y_m),
            "yaw_rad": float(gt.mount.yaw_rad),
        },
    }
    if gt.mount.roll_rad or gt.mount.pitch_rad:  # a level mount's file stays as it always was
        data["camera_mount"].update(roll_rad=float(gt.mount.roll_rad), pitch_rad=float(gt.mount.pitch_rad))
    if gt.room is not None:
        r = gt.room
        data["room"] = {
            "x": fl([r.x_min_m, r.x_max_m]),
            "y": fl([r.y_min_m, r.y_max_m]),
            "wall_height_m": r.wall_height_m,
        }
    data["objects"] = [
        {"id": o.id, "label": o.label, "position": fl(o.position_m), "size": fl(o.size_m)} for o in gt.objects
    ]
    data["tables"] = [
        {"id": t.id, "position": fl(t.position_m), "size": fl(t.size_m), "object_id": t.object_id} for t in gt.tables
    ]
    data["distractors"] = [
        {
            "id": d.id,
            "kind": d.kind,
            "label": d.label,
            "color_rgb": [int(v) for v in d.color_rgb],
            "center": fl(d.center_m),
            "size": fl(d.size_m),
            "yaw": round(float(d.yaw_rad), 6),
        }
        for d in gt.distractors
    ]
    data["simulation"] = _plain(dict(gt.simulation))
    return data


def _plain(value: Any) -> Any:
    """numpy scalars and arrays, tuples -> plain YAML-safe values."""
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def ground_truth_path(bag_dir: str | os.PathLike[str]) -> Path:
    return Path(bag_dir) / GROUND_TRUTH_FILE


def write_ground_truth(bag_dir: str | os.PathLike[str], gt: GroundTruth) -> Path:
    """Write ``ground_truth.yaml`` into the bag directory (which must exist)."""
    path = ground_truth_path(bag_dir)
    with path.open("w") as stream:
        yaml.safe_dump(ground_truth_to_dict(gt), stream, sort_keys=False, default_flow_style=None, width=120)
    return path


def load_ground_truth(bag_dir: str | os.PathLike[str]) -> GroundTruth:
    """Read ``ground_truth.yaml`` of a bag directory (or that file given directly)."""
    path = Path(bag_dir)
    if path.is_dir():
        path = path / GROUND_TRUTH_FILE
    try:
        with path.open() as stream:
            data = yaml.safe_load(stream)
    except FileNotFoundError as exc:
        raise UserError(f"no ground truth: {path} not found (only simulated bags have one)") from exc
    except (OSError, yaml.YAMLError, UnicodeDecodeError) as exc:  # a binary file is not UTF-8
        raise UserError(f"cannot read {path}: {exc}".splitlines()[0]) from exc
    try:
        return ground_truth_from_dict(data)
    except (KeyError, TypeError, ValueError, OverflowError) as exc:  # OverflowError: int(.inf)
        detail = f"missing key {exc}" if isinstance(exc, KeyError) else str(exc)
        raise UserError(f"{path}: malformed ground truth: {detail}") from exc
