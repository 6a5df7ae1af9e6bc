"""A built map as ROS messages: MarkerArray, nav_msgs/Path and objslam_msgs/ObjectMap."""

from __future__ import annotations

from builtin_interfaces.msg import Duration, Time
from geometry_msgs.msg import Point, Pose, PoseStamped, Quaternion
from nav_msgs.msg import Path
from std_msgs.msg import ColorRGBA, Header
from visualization_msgs.msg import Marker, MarkerArray

from objslam_common.catalog import Catalog
from objslam_common.geometry import quaternion_from_yaw
from objslam_common.ros.conversions import time_from_ns
from objslam_mapper.map_file import BuiltMap, MappedObject
from objslam_msgs.msg import MapObject, ObjectMap

OBJECTS_NS = "objects"
LABELS_NS = "labels"
REJECTED_NS = "rejected"
REJECTED_LABELS_NS = "rejected_labels"
_LABEL_HEIGHT_M = 0.15
_UNKNOWN_RGB = (128, 128, 128)


def _color(obj: MappedObject, catalog: Catalog, alpha: float) -> ColorRGBA:
    rgb = catalog[obj.label].color_rgb if obj.label in catalog else _UNKNOWN_RGB
    return ColorRGBA(r=rgb[0] / 255.0, g=rgb[1] / 255.0, b=rgb[2] / 255.0, a=float(alpha))


def _object_markers(obj: MappedObject, header: Header, catalog: Catalog, ns: str, label_ns: str) -> list[Marker]:
    x, y, z_base = obj.position_m
    diameter, height = obj.size_m
    cylinder = Marker(header=header, ns=ns, id=int(obj.id), type=Marker.CYLINDER, action=Marker.ADD)
    cylinder.pose = Pose(position=Point(x=x, y=y, z=z_base + height / 2.0), orientation=Quaternion(w=1.0))
    cylinder.scale.x = cylinder.scale.y = float(diameter)
    cylinder.scale.z = float(height)
    cylinder.color = _color(obj, catalog, obj.existence_probability)
    cylinder.lifetime = Duration()
    text = Marker(header=header, ns=label_ns, id=int(obj.id), type=Marker.TEXT_VIEW_FACING, action=Marker.ADD)
    text.pose = Pose(position=Point(x=x, y=y, z=z_base + height + _LABEL_HEIGHT_M), orientation=Quaternion(w=1.0))
    text.scale.z = _LABEL_HEIGHT_M
    text.color = ColorRGBA(r=1.0, g=1.0, b=1.0, a=1.0)
    text.text = f"{obj.label} #{obj.id} p={obj.existence_probability:.2f}"
    return [cylinder, text]


def to_marker_array(built: BuiltMap, catalog: Catalog, stamp: Time) -> MarkerArray:
    """DELETEALL first, then a CYLINDER (alpha = existence probability) and a TEXT per object."""
    header = Header(stamp=stamp, frame_id=built.frame_id)
    markers = [Marker(header=header, action=Marker.DELETEALL)]
    for obj in built.objects:
        markers += _object_markers(obj, header, catalog, OBJECTS_NS, LABELS_NS)
    for obj in built.rejected:
        markers += _object_markers(obj, header, catalog, REJECTED_NS, REJECTED_LABELS_NS)
    return MarkerArray(markers=markers)


def to_path(built: BuiltMap, stamp: Time) -> Path:
    header = Header(stamp=stamp, frame_id=built.frame_id)
    poses = []
    for pose in built.trajectory:
        qx, qy, qz, qw = quaternion_from_yaw(pose.theta_rad)
        stamped = PoseStamped(header=Header(stamp=time_from_ns(pose.stamp_ns), frame_id=built.frame_id))
        stamped.pose = Pose(position=Point(x=pose.x_m, y=pose.y_m), orientation=Quaternion(x=qx, y=qy, z=qz, w=qw))
        poses.append(stamped)
    return Path(header=header, poses=poses)


def _map_object(obj: MappedObject) -> MapObject:
    x, y, z_base = obj.position_m
    return MapObject(
        id=int(obj.id),
        label=obj.label,
        position=Point(x=float(x), y=float(y), z=float(z_base)),
        diameter=float(obj.size_m[0]),
        height=float(obj.size_m[1]),
        existence_probability=float(obj.existence_probability),
        position_covariance=[float(v) for row in obj.position_covariance for v in row],
        size_covariance=[float(v) for row in obj.size_covariance for v in row],
        measurement_count=int(obj.measurement_count),
        existence_probability_by_chain=[float(p) for p in obj.existence_by_chain],
    )


def to_object_map(built: BuiltMap, stamp: Time) -> ObjectMap:
    diagnostics = built.diagnostics
    return ObjectMap(
        header=Header(stamp=stamp, frame_id=built.frame_id),
        objects=[_map_object(o) for o in built.objects],
        rejected=[_map_object(o) for o in built.rejected],
        samples=int(diagnostics.get("samples", 0)),
        burn_in=int(diagnostics.get("burn_in", 0)),
        **dict(zip(("chains", "converged", "rhat_max"), chain_agreement(built), strict=True)),
    )


def chain_agreement(built: BuiltMap) -> tuple[int, bool, float]:
    """(chains, converged, largest R-hat) of a map, as the messages carry them: not converged
    and R-hat 0 with one chain, whose convergence cannot be judged."""
    convergence = built.diagnostics.get("convergence") or {}
    rhat = convergence.get("rhat_max")
    return (
        int(convergence.get("chains", built.diagnostics.get("chains", 1))),
        bool(convergence.get("converged")),
        float(rhat) if rhat is not None else 0.0,
    )
