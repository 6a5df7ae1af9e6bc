"""Pictures of a built map, like the paper's Figures 2 and 3 (PNG, matplotlib without a display).

- :func:`top_down_figure`: the map seen from above in its ``odom`` frame: each object a
  circle of its diameter in its class colour with opacity = existence probability, its
  2-sigma xy covariance ellipse, the trajectory, rejected identities dashed and crossed (unlabelled),
  and, when the ground truth is known, the real objects (dashed black circles) and
  distractors brought into the map frame by the same SE(2) alignment ``objslam eval`` uses.
- :func:`overlay_figure`: the map's objects projected back into one omnidirectional image
  with the map's own pose at that image: each object's predicted silhouette sector
  (bearing +- half width between the elevations of its lower and upper edges, from
  :func:`objslam_mapper.model.slice_model.predict_slices`) drawn through the camera model;
  objects with existence probability <= 1/2 are dashed and circled.
- :func:`write_figures` writes both kinds for a map (and a bag) and returns the paths.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib import patheffects
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Circle, Ellipse, Patch
from numpy.typing import NDArray

from objslam_common.cameras.unified import DEFAULT_CAMERA, UnifiedCamera
from objslam_common.catalog import Catalog, load_catalog
from objslam_common.mount import CameraMount
from objslam_mapper.map_file import BuiltMap, MappedObject
from objslam_mapper.model.slice_model import predict_slices
from objslam_tools.bag import Bag, ImageFrame, decode_rgb, open_bag
from objslam_tools.errors import UserError
from objslam_tools.evaluate import Alignment, Reference, align_map, load_reference, map_track

logger = logging.getLogger(__name__)

DEFAULT_OVERLAY_COUNT = 3
_UNKNOWN_RGB = (128, 128, 128)
_MIN_ALPHA = 0.06  # an object with P ~ 0 must still be visible as an outline
_DPI = 110
_OVERLAY_MIN_SIZE_PX = 720


def _rgb(catalog: Catalog | None, label: str) -> tuple[float, float, float]:
    rgb = catalog[label].color_rgb if catalog is not None and label in catalog else _UNKNOWN_RGB
    return (rgb[0] / 255.0, rgb[1] / 255.0, rgb[2] / 255.0)


_REJECTED_ELLIPSE_MAX_STDDEV_M = 0.3  # the default spurious-object threshold


def _largest_stddev(cov_xy: NDArray[np.float64]) -> float:
    values = np.linalg.eigvalsh(0.5 * (cov_xy + cov_xy.T)) if np.all(np.isfinite(cov_xy)) else [np.inf]
    return float(np.sqrt(max(float(np.max(values)), 0.0)))


def _ellipse(xy: NDArray[np.float64], cov_xy: NDArray[np.float64], sigmas: float = 2.0) -> Ellipse | None:
    """The ``sigmas``-sigma ellipse of a 2x2 covariance, None if it is degenerate."""
    cov = 0.5 * (cov_xy + cov_xy.T)
    values, vectors = np.linalg.eigh(cov)
    if not np.all(np.isfinite(values)) or values[-1] <= 0.0:
        return None
    values = np.maximum(values, 0.0)
    angle = np.degrees(np.arctan2(vectors[1, -1], vectors[0, -1]))
    return Ellipse(
        tuple(xy),
        width=2 * sigmas * np.sqrt(values[-1]),
        height=2 * sigmas * np.sqrt(values[0]),
        angle=angle,
        fill=False,
        linestyle=":",
        linewidth=1.0,
        edgecolor="0.2",
    )


def _alignment_or_none(built_map: BuiltMap, reference: Reference | None) -> Alignment | None:
    if reference is None:
        return None
    try:
        return align_map(built_map, reference.ground_truth_track)
    except UserError as exc:
        logger.warning("ground truth not drawn: %s", exc)
        return None


def top_down_figure(
    built_map: BuiltMap,
    reference: Reference | None = None,
    catalog: Catalog | None = None,
    title: str | None = None,
) -> Figure:
    """The Figure-2-style top view (module docstring), in the map's frame."""
    fig = Figure(figsize=(8.0, 8.0), dpi=_DPI)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    points: list[NDArray[np.float64]] = []

    traj = built_map.trajectory_array()
    if len(traj):
        ax.plot(traj[:, 0], traj[:, 1], "-", color="0.35", linewidth=1.2, zorder=2)
        ax.plot(traj[0, 0], traj[0, 1], "o", color="0.35", markersize=5, zorder=2)
        step = max(1, len(traj) // 25)
        ax.quiver(
            traj[::step, 0], traj[::step, 1], np.cos(traj[::step, 2]), np.sin(traj[::step, 2]),
            color="0.35", angles="xy", scale_units="inches", scale=4.0, width=0.003, zorder=2,
        )  # fmt: skip
        points.append(traj[:, :2])

    alignment = _alignment_or_none(built_map, reference)
    if alignment is not None and reference is not None:
        truth = reference.ground_truth
        for t in truth.objects:
            xy = alignment.to_map(t.position_m[:2])[0]
            ax.add_patch(
                Circle(tuple(xy), t.size_m[0] / 2, fill=False, linestyle="--", edgecolor="k", linewidth=0.9, zorder=6)
            )
            ax.plot(*xy, "+", color="k", markersize=5, zorder=6)
            points.append(xy[None, :])
        for d in truth.distractors:
            corners = alignment.to_map(d.corners_m()[:, :2])
            closed = np.vstack([corners, corners[:1]])
            ax.plot(closed[:, 0], closed[:, 1], "-", color=_rgb(catalog, d.label), linewidth=3, alpha=0.6)
            ax.plot(closed[:, 0], closed[:, 1], "-", color="k", linewidth=0.6)
            points.append(corners)

    def draw(obj: MappedObject, rejected: bool) -> None:
        color = _rgb(catalog, obj.label)
        xy = np.asarray(obj.position_m[:2], dtype=float)
        alpha = float(np.clip(obj.existence_probability, _MIN_ALPHA, 1.0))
        radius = max(obj.size_m[0] / 2, 0.02)
        ax.add_patch(Circle(tuple(xy), radius, facecolor=(*color, alpha), edgecolor="none", zorder=4))
        ax.add_patch(
            Circle(
                tuple(xy), radius, fill=False, edgecolor=color, linewidth=1.4, linestyle="--" if rejected else "-",
                zorder=5,
            )
        )  # fmt: skip
        if rejected:
            ax.plot(*xy, "x", color="k", markersize=7, markeredgewidth=1.3, zorder=6)
        cov_xy = np.asarray(obj.position_covariance, dtype=float)[:2, :2]
        # A rejected identity is often spurious (metres of uncertainty): its ellipse would only
        # hide the map. Mapped objects always get theirs.
        ellipse = _ellipse(xy, cov_xy)
        if ellipse is not None and not (rejected and _largest_stddev(cov_xy) > _REJECTED_ELLIPSE_MAX_STDDEV_M):
            ellipse.set_zorder(5)
            ax.add_patch(ellipse)
        if not rejected:  # rejected identities often pile up where one real object is: their labels would hide it
            ax.annotate(
                f"{obj.id} P={obj.existence_probability:.2f}", tuple(xy), xytext=(6, 6),
                textcoords="offset points", fontsize=7, color="0.1", zorder=7,
            )  # fmt: skip
        if not rejected:  # far-off rejected identities would shrink the map to a corner of the picture
            points.append(xy[None, :] + np.array([[-radius, -radius], [radius, radius]]))

    for obj in built_map.rejected:
        draw(obj, rejected=True)
    for obj in built_map.objects:
        draw(obj, rejected=False)

    labels = sorted({o.label for o in (*built_map.objects, *built_map.rejected)})
    handles = [Patch(facecolor=_rgb(catalog, lab), edgecolor=_rgb(catalog, lab), label=lab) for lab in labels]
    handles += [
        Line2D([], [], color="0.35", linewidth=1.2, marker="o", markevery=[0], label="trajectory (start o)"),
        Line2D([], [], color="0.2", linestyle=":", label="2-sigma position"),
        Line2D([], [], color="0.3", linestyle="--", marker="x", markeredgecolor="k", label="rejected (P <= 1/2)"),
    ]
    if alignment is not None:
        handles += [
            Line2D([], [], color="k", linestyle="--", marker="+", label="ground truth"),
            Line2D([], [], color="0.5", linewidth=3, alpha=0.6, label="distractor"),
        ]
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)

    if points:
        allp = np.vstack(points)
        lo, hi = allp.min(axis=0) - 0.5, allp.max(axis=0) + 0.5
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal", adjustable="box")
    ax.grid(True, linewidth=0.4, alpha=0.5)
    ax.set_xlabel(f"x [m] ({built_map.frame_id})")
    ax.set_ylabel(f"y [m] ({built_map.frame_id})")
    subtitle = f"{len(built_map.objects)} objects, {len(built_map.rejected)} rejected; opacity = P(exists)"
    if alignment is not None:
        subtitle += f"; trajectory ATE {alignment.ate_m:.3f} m"
    ax.set_title(f"{title}\n{subtitle}" if title else subtitle, fontsize=10)
    return fig


def _sector_outline(
    camera: UnifiedCamera, bearing: float, width: float, el_bottom: float, el_top: float, samples: int = 24
) -> NDArray[np.float64]:
    """(K, 2) pixel polygon of a slice: outer arc, inner arc back; NaN points dropped."""
    az = np.linspace(bearing - width / 2, bearing + width / 2, samples)
    u_top, v_top = camera.project(az, np.full_like(az, el_top))
    u_bot, v_bot = camera.project(az[::-1], np.full_like(az, el_bottom))
    poly = np.column_stack([np.concatenate([u_top, u_bot]), np.concatenate([v_top, v_bot])])
    return poly[np.all(np.isfinite(poly), axis=1)]


def overlay_figure(
    built_map: BuiltMap,
    frame: ImageFrame,
    camera: UnifiedCamera,
    mount: CameraMount | None = None,
    catalog: Catalog | None = None,
    title: str | None = None,
) -> Figure:
    """The Figure-3-style overlay of the map's objects on one image (module docstring)."""
    mount = mount or CameraMount()
    camera = mount.level_view(camera)  # the slice model's directions are the level frame's
    rgb = decode_rgb(frame)
    height, width = rgb.shape[:2]
    # Small images are shown enlarged so outlines and labels stay legible.
    scale = max(1.0, _OVERLAY_MIN_SIZE_PX / max(height, width))
    title_px = 40
    fig = Figure(figsize=(width * scale / 100, (height * scale + title_px) / 100), dpi=100)
    FigureCanvasAgg(fig)
    ax = fig.add_axes((0.0, 0.0, 1.0, height * scale / (height * scale + title_px)))
    ax.imshow(rgb, interpolation="nearest")
    ax.set_xlim(0, width)
    ax.set_ylim(height, 0)
    ax.axis("off")

    track = map_track(built_map)
    if len(track) == 0:
        raise UserError("the map has no trajectory: cannot place its objects in an image")
    pose = track.interpolate([frame.stamp_ns])[0]
    objects = [(o, False) for o in built_map.objects] + [(o, True) for o in built_map.rejected]
    drawn = 0
    for obj, rejected in objects:
        pred = predict_slices(pose, obj.position_m, obj.size_m, mount, jacobians=False)
        if not pred.valid[0]:
            continue
        bearing, width, el_bottom, el_top = pred.values[0]  # slice_model.COMPONENTS order
        poly = _sector_outline(camera, bearing, width, el_bottom, el_top)
        if len(poly) < 3:
            continue
        low = rejected or obj.existence_probability <= 0.5
        color = _rgb(catalog, obj.label)
        halo = [patheffects.withStroke(linewidth=3.2, foreground="white")]
        closed = np.vstack([poly, poly[:1]])
        ax.plot(closed[:, 0], closed[:, 1], linestyle="--" if low else "-", color=color, linewidth=1.6,
                path_effects=halo)  # fmt: skip
        centre = poly.mean(axis=0)
        if low:
            extent = float(np.max(np.linalg.norm(poly - centre, axis=1)))
            ax.add_patch(
                Circle(tuple(centre), extent + 8, fill=False, edgecolor="white", linestyle="--", linewidth=1.2)
            )
        ax.annotate(
            f"{obj.id} P={obj.existence_probability:.2f}", tuple(poly[0]), xytext=(3, -3), textcoords="offset points",
            fontsize=8, color="white", path_effects=[patheffects.withStroke(linewidth=2, foreground="black")],
        )  # fmt: skip
        drawn += 1
    stamp = f"t = {frame.stamp_ns * 1e-9:.3f} s"
    heading = f"{title}: {stamp}" if title else stamp
    ax.set_title(
        f"{heading}\n{drawn} map objects projected with the map's pose (dashed, circled: P <= 1/2)", fontsize=9
    )
    return fig


def _choose_frames(count: int, frames: Sequence[int] | None) -> list[int]:
    if count == 0:
        return []
    if frames is None:
        n = min(DEFAULT_OVERLAY_COUNT, count)
        return sorted({round(count * (k + 1) / (n + 1)) for k in range(n)})
    out = []
    for f in frames:
        index = f + count if f < 0 else f
        if not 0 <= index < count:
            raise UserError(f"frame {f} is out of range: the bag has {count} images")
        out.append(index)
    return sorted(set(out))


def _reference_or_none(bag: Bag) -> Reference | None:
    try:
        return load_reference(bag.path)
    except UserError as exc:
        logger.info("no ground truth in the figures: %s", exc)
        return None


def write_figures(
    built_map: BuiltMap,
    out_dir: str | os.PathLike[str],
    bag: str | os.PathLike[str] | Bag | None = None,
    *,
    frames: Sequence[int] | None = None,
    catalog: Catalog | None = None,
    mount: CameraMount | None = None,
    prefix: str = "map",
) -> list[Path]:
    """Write ``<prefix>_top_down.png`` and, with a bag that has images, ``<prefix>_overlay_<index>.png``.

    ``frames`` are image indices in the bag (negative counts from the end); default: three
    spread over the run. With a simulated bag the ground truth is drawn in the top view and
    its camera mount is used for the overlays (else ``mount``, default CameraMount()).
    """
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"cannot create figure folder {out}: {exc.strerror or exc}") from exc
    catalog = catalog if catalog is not None else load_catalog()
    opened = bag if isinstance(bag, Bag) or bag is None else open_bag(bag)
    reference = _reference_or_none(opened) if opened is not None else None
    if mount is None:
        mount = reference.ground_truth.mount if reference is not None else CameraMount()
    title = f"{prefix}" + (f" ({opened.path.name})" if opened is not None else "")

    image_topic, chosen = None, []
    if opened is not None:
        try:
            image_topic = opened.image_topic()
            chosen = _choose_frames(opened.topics[image_topic].count, frames)
        except UserError as exc:
            if frames:
                raise
            logger.info("no overlays: %s", exc)

    paths = [_save(top_down_figure(built_map, reference, catalog, title), out / f"{prefix}_top_down.png")]
    chains = chains_figure(built_map, title)
    if chains is not None:
        paths.append(_save(chains, out / f"{prefix}_chains.png"))
    if opened is None or image_topic is None or not chosen:
        return paths
    camera = _camera(opened)
    wanted = set(chosen)
    for index, frame in enumerate(opened.images(image_topic)):
        if index in wanted:
            fig = overlay_figure(built_map, frame, camera, mount, catalog, title=f"{title} image {index}")
            paths.append(_save(fig, out / f"{prefix}_overlay_{index:04d}.png"))
            wanted.discard(index)
            if not wanted:
                break
    return paths


def chains_figure(built_map: BuiltMap, title: str = "map") -> Figure | None:
    """Per chain, the trace of the log target and of the number of objects, burn-in included
    (from the map's ``diagnostics.chain_runs``); None for a map without chain traces."""
    runs = [r for r in built_map.diagnostics.get("chain_runs") or [] if r.get("trace")]
    if not runs:
        return None
    fig = Figure(figsize=(9.0, 6.0), dpi=_DPI)
    FigureCanvasAgg(fig)
    top, bottom = fig.subplots(2, 1, sharex=True)
    for run in runs:
        trace = run["trace"]
        steps = trace["every_steps"] * (1 + np.arange(len(trace["log_target"])))
        name = f"chain {run['chain']} ({run['start']})"
        top.plot(steps, trace["log_target"], linewidth=1.0, label=name)
        bottom.step(steps, trace["objects"], where="post", linewidth=1.0, label=name)
    burn_in = built_map.diagnostics.get("burn_in")
    for ax in (top, bottom):
        if burn_in:
            ax.axvline(burn_in, color="0.5", linestyle=":", linewidth=1.0)
        ax.grid(True, alpha=0.3)
    convergence = built_map.diagnostics.get("convergence") or {}
    verdict = {True: "converged", False: "NOT converged", None: "one chain"}[convergence.get("converged")]
    top.set_title(f"{title}: chains ({verdict}; R-hat max {convergence.get('rhat_max')}); dotted: end of burn-in")
    top.set_ylabel("log target")
    bottom.set_ylabel("objects")
    bottom.set_xlabel("step")
    top.legend(fontsize=8, loc="lower right")
    # Dispersed starts begin thousands of nats below the mode: show the part where chains meet.
    finals = [v for r in runs for v in r["trace"]["log_target"][len(r["trace"]["log_target"]) // 2 :]]
    if finals:
        low, high = min(finals), max(finals)
        pad = max(10.0, 0.2 * (high - low))
        top.set_ylim(low - pad, high + pad)
    return fig


def _camera(bag: Bag) -> UnifiedCamera:
    try:
        return bag.read_camera()
    except UserError as exc:
        logger.warning("%s; using the default camera", exc)
        return DEFAULT_CAMERA


def _save(fig: Figure, path: Path) -> Path:
    try:
        # "tight" keeps the legend, which sits outside the axes, in the picture.
        fig.savefig(path, dpi=fig.dpi, bbox_inches="tight", pad_inches=0.1)
    except OSError as exc:
        raise UserError(f"cannot write {path}: {exc.strerror or exc}") from exc
    logger.debug("wrote %s", path)
    return path
