"""The built map as plain data, and its YAML file (docs/design.md, "Outputs").

Frame: the odom frame of ``/odom``. Positions are ``[x, y, z_base]`` (z of the object's
base), sizes ``[diameter, height]``, all in metres; trajectory stamps are float seconds
in the file and integer nanoseconds in memory.
"""

from __future__ import annotations

import logging
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from objslam_common.config import read_yaml
from objslam_mapper.errors import MapperError

logger = logging.getLogger(__name__)


class MapFileError(MapperError, ValueError):
    """A map file that cannot be read or written."""


@dataclass(frozen=True)
class MappedObject:
    """One object identity of the map (paper Algorithm 1)."""

    id: int
    label: str
    position_m: tuple[float, float, float]  # x, y, z_base in the odom frame
    size_m: tuple[float, float]  # diameter, height
    existence_probability: float  # P(ID|Z)
    position_covariance: tuple[tuple[float, ...], ...] = ((0.0,) * 3,) * 3  # m^2, 3x3
    size_covariance: tuple[tuple[float, ...], ...] = ((0.0,) * 2,) * 2  # m^2, 2x2
    measurement_count: int = 0
    existence_by_chain: tuple[float, ...] = ()  # P(ID|Z) of each chain's samples alone (several chains)


@dataclass(frozen=True)
class TrajectoryPose:
    stamp_ns: int
    x_m: float
    y_m: float
    theta_rad: float


@dataclass(frozen=True)
class BuiltMap:
    objects: tuple[MappedObject, ...]  # P(ID|Z) > 1/2
    rejected: tuple[MappedObject, ...] = ()  # the other identities, for figures
    trajectory: tuple[TrajectoryPose, ...] = ()
    diagnostics: dict[str, Any] = field(default_factory=dict)
    frame_id: str = "odom"

    def trajectory_array(self) -> np.ndarray:
        """(N, 3) array of x, y, theta."""
        return np.array([[p.x_m, p.y_m, p.theta_rad] for p in self.trajectory]).reshape(-1, 3)


def _matrix(value: Any, n: int) -> tuple[tuple[float, ...], ...]:
    arr = np.asarray(value, dtype=float).reshape(n, n)
    return tuple(tuple(float(v) for v in row) for row in arr)


def _plain(value: Any) -> Any:
    """numpy scalars/arrays and tuples -> YAML-safe Python values."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return _plain(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    return value


def _object_to_dict(obj: MappedObject) -> dict[str, Any]:
    entry = {
        "id": int(obj.id),
        "label": obj.label,
        "position": [float(v) for v in obj.position_m],
        "size": [float(v) for v in obj.size_m],
        "existence_probability": float(obj.existence_probability),
        "position_covariance": _plain(obj.position_covariance),
        "size_covariance": _plain(obj.size_covariance),
        "measurement_count": int(obj.measurement_count),
    }
    if obj.existence_by_chain:
        entry["existence_probability_by_chain"] = [float(p) for p in obj.existence_by_chain]
    return entry


def _object_from_dict(d: dict[str, Any]) -> MappedObject:
    return MappedObject(
        id=int(d["id"]),
        label=str(d["label"]),
        position_m=_triple(d["position"]),
        size_m=_pair(d["size"]),
        existence_probability=float(d["existence_probability"]),
        position_covariance=_matrix(d.get("position_covariance", np.zeros((3, 3))), 3),
        size_covariance=_matrix(d.get("size_covariance", np.zeros((2, 2))), 2),
        measurement_count=int(d.get("measurement_count", 0)),
        existence_by_chain=tuple(float(p) for p in d.get("existence_probability_by_chain") or ()),
    )


def _triple(value: Any) -> tuple[float, float, float]:
    x, y, z = (float(v) for v in value)
    return (x, y, z)


def _pair(value: Any) -> tuple[float, float]:
    a, b = (float(v) for v in value)
    return (a, b)


def map_to_dict(built: BuiltMap) -> dict[str, Any]:
    return {
        "frame_id": built.frame_id,
        "objects": [_object_to_dict(o) for o in built.objects],
        "rejected": [_object_to_dict(o) for o in built.rejected],
        "trajectory": [
            # float seconds per the contract; stamp_ns keeps the exact stamp for a lossless read back
            {
                "stamp": p.stamp_ns * 1e-9,
                "x": float(p.x_m),
                "y": float(p.y_m),
                "theta": float(p.theta_rad),
                "stamp_ns": int(p.stamp_ns),
            }
            for p in built.trajectory
        ],
        "diagnostics": _plain(built.diagnostics),
    }


def map_from_dict(data: dict[str, Any]) -> BuiltMap:
    return BuiltMap(
        objects=tuple(_object_from_dict(o) for o in data.get("objects") or []),
        rejected=tuple(_object_from_dict(o) for o in data.get("rejected") or []),
        trajectory=tuple(
            TrajectoryPose(
                stamp_ns=int(p["stamp_ns"]) if "stamp_ns" in p else round(float(p["stamp"]) * 1e9),
                x_m=float(p["x"]),
                y_m=float(p["y"]),
                theta_rad=float(p["theta"]),
            )
            for p in data.get("trajectory") or []
        ),
        diagnostics=dict(data.get("diagnostics") or {}),
        frame_id=str(data.get("frame_id", "odom")),
    )


def write_map(path: str | os.PathLike[str], built: BuiltMap) -> Path:
    """Write the map YAML atomically (a reader never sees half a file)."""
    path = Path(path)
    if path.exists():
        logger.warning("replacing existing map file %s", path)
    tmp_name = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile("w", dir=path.parent, prefix=f".{path.name}.", delete=False) as tmp:
            tmp_name = tmp.name
            yaml.safe_dump(map_to_dict(built), tmp, sort_keys=False, default_flow_style=None, width=120)
        # A temporary file is private (0600); the map is an ordinary file, as open() would make it.
        os.chmod(tmp_name, 0o666 & ~_umask())
        os.replace(tmp_name, path)
    except OSError as exc:
        if tmp_name is not None:
            Path(tmp_name).unlink(missing_ok=True)
        raise MapFileError(f"cannot write map file {path}: {exc.strerror or exc}") from exc
    return path


def _umask() -> int:
    mask = os.umask(0o022)  # the only way to read it is to set it
    os.umask(mask)
    return mask


def read_map(path: str | os.PathLike[str]) -> BuiltMap:
    data = read_yaml(path)
    if not isinstance(data, dict) or "objects" not in data:
        raise MapFileError(f"{path}: not an objslam map file (no 'objects')")
    try:
        return map_from_dict(data)
    except (KeyError, TypeError, ValueError, OverflowError) as exc:  # OverflowError: int(.inf)
        detail = f"missing key {exc}" if isinstance(exc, KeyError) else str(exc)
        raise MapFileError(f"{path}: malformed map file: {detail}") from exc
