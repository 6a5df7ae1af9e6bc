"""Perspective and fisheye cameras: OpenCV's pinhole model with its distortion (``plumb_bob``,
``rational_polynomial``) and OpenCV's fisheye model (``equidistant``, Kannala-Brandt).

Both act on the optical coordinates ``(X, Y, Z) = (-y, -z, x)`` of a camera-frame ray: the
optical axis is the camera frame's x axis. The formulas are OpenCV's (``cv2.projectPoints``,
``cv2.fisheye.projectPoints``), written out in numpy because they run vectorised on the
detector's pixel grids and their inverses need a solve per pixel
(``cv2.undistortPoints`` stops after a fixed number of fixed-point steps, not enough for
strong distortion; ours is Newton's method to 1e-12). The tests check both directions
against OpenCV.

**Field of view.** A distortion polynomial folds back beyond some radius: past it, two rays
land on one pixel. Each model finds, once, the largest angle from the optical axis up to
which its radial mapping still grows, and treats rays beyond it as not seen (``valid``
False), as it does rays behind a perspective camera.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from objslam_common.cameras.rays import (
    camera_from_optical,
    normalized,
    optical_from_camera,
    project_directions,
    unproject_directions,
)
from objslam_common.errors import CameraModelError

_NEWTON_STEPS = 30
_FOLD_SAMPLES = 20_000


def _first_fold(radial_map, limit: float) -> float:
    """The largest t in (0, limit] up to which ``radial_map(t)`` strictly grows."""
    t = np.linspace(0.0, limit, _FOLD_SAMPLES)
    grows = np.diff(radial_map(t)) > 0.0
    if grows.all():
        return limit
    return float(t[int(np.argmin(grows))])


@dataclass(frozen=True)
class _Lens:
    """What the perspective and fisheye models share: the image size, ``K`` and ``d`` of
    the CameraInfo, the pixel <-> normalized-coordinate step, and azimuth/elevation access
    to the rays, the interface the detector's panorama, its overlay and the renderer use (as
    :class:`UnifiedCamera` has it)."""

    width_px: int
    height_px: int
    fx: float
    fy: float
    cx: float
    cy: float
    d: tuple[float, ...]

    def _check(self, model: str, d_length: int) -> None:
        if len(self.d) != d_length:
            raise CameraModelError(f"{model}: d must hold {d_length} coefficients, got {len(self.d)}")
        if self.width_px <= 0 or self.height_px <= 0:
            raise CameraModelError(f"{model}: image size must be positive, got {self.width_px}x{self.height_px}")
        if not all(math.isfinite(v) for v in (self.fx, self.fy, *self.d)):
            raise CameraModelError(
                f"{model}: calibration values must be finite, got k={[self.fx, self.fy]}, d={list(self.d)}"
            )
        if self.fx <= 0.0 or self.fy <= 0.0:
            raise CameraModelError(f"{model}: focal lengths must be positive, got fx={self.fx}, fy={self.fy}")

    def _pixels(self, x: NDArray[np.float64], y: NDArray[np.float64]) -> NDArray[np.float64]:
        """(N, 2) pixels of distorted normalized coordinates."""
        return np.stack([self.fx * x + self.cx, self.fy * y + self.cy], axis=1)

    def _normalized(self, uv: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Distorted normalized coordinates of (N, 2) pixels."""
        p = np.atleast_2d(np.asarray(uv, dtype=float))
        return (p[:, 0] - self.cx) / self.fx, (p[:, 1] - self.cy) / self.fy

    def project_rays(self, rays: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        raise NotImplementedError

    def unproject_pixels(self, uv: ArrayLike) -> NDArray[np.float64]:
        raise NotImplementedError

    def project(self, azimuth_rad: ArrayLike, elevation_rad: ArrayLike) -> tuple[NDArray, NDArray]:
        """Pixel (u, v) of directions (broadcast); NaN where a direction is not seen."""
        return project_directions(self.project_rays, azimuth_rad, elevation_rad)

    def unproject(self, u_px: ArrayLike, v_px: ArrayLike) -> tuple[NDArray, NDArray]:
        """Direction (azimuth, elevation) seen at pixels (u, v) (broadcast)."""
        return unproject_directions(self.unproject_pixels, u_px, v_px)


@dataclass(frozen=True)
class PinholeCamera(_Lens):
    """``plumb_bob`` (d = k1, k2, p1, p2, k3) or ``rational_polynomial`` (d = k1, k2, p1, p2,
    k3, k4, k5, k6): OpenCV's pinhole model with radial and tangential distortion."""

    distortion_model: str
    max_tan: float = field(init=False, repr=False, compare=False)  # edge of the field of view

    D_LENGTHS: ClassVar[dict[str, int]] = {"plumb_bob": 5, "rational_polynomial": 8}

    def __post_init__(self) -> None:
        expected = self.D_LENGTHS.get(self.distortion_model)
        if expected is None:
            raise CameraModelError(f"PinholeCamera takes {' or '.join(self.D_LENGTHS)}, got {self.distortion_model!r}")
        self._check(self.distortion_model, expected)
        # Beyond this tangent of the angle off the axis the radial mapping folds back (module
        # docstring); 10 is ~84 degrees, past any real perspective lens.
        object.__setattr__(self, "max_tan", _first_fold(lambda r: r * self._radial(r * r), 10.0))

    @property
    def coefficients(self) -> tuple[float, float, float, float, float, float, float, float]:
        """k1, k2, p1, p2, k3, k4, k5, k6 (zeros where the model has none)."""
        d = (*self.d, 0.0, 0.0, 0.0)
        return d[0], d[1], d[2], d[3], d[4], d[5], d[6], d[7]

    def _radial(self, r2: NDArray[np.float64]) -> NDArray[np.float64]:
        k1, k2, _, _, k3, k4, k5, k6 = self.coefficients
        return (1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1.0 + r2 * (k4 + r2 * (k5 + r2 * k6)))

    def _distort(self, a: NDArray[np.float64], b: NDArray[np.float64]) -> tuple[NDArray, NDArray]:
        _, _, p1, p2, *_ = self.coefficients
        r2 = a * a + b * b
        radial = self._radial(r2)
        return (
            a * radial + 2.0 * p1 * a * b + p2 * (r2 + 2.0 * a * a),
            b * radial + p1 * (r2 + 2.0 * b * b) + 2.0 * p2 * a * b,
        )

    def project_rays(self, rays: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        """(N, 2) pixels of camera-frame rays, and whether each is in the field of view
        (in front of the camera and before the distortion folds back); NaN where not."""
        optical = optical_from_camera(rays)
        z = optical[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            a, b = optical[:, 0] / z, optical[:, 1] / z
            valid = (z > 1e-12) & (np.hypot(a, b) < self.max_tan)
        a, b = np.where(valid, a, np.nan), np.where(valid, b, np.nan)
        return self._pixels(*self._distort(a, b)), valid

    def unproject_pixels(self, uv: ArrayLike) -> NDArray[np.float64]:
        """(N, 3) unit camera-frame rays seen at pixels (u, v): Newton's method on the distortion."""
        x_d, y_d = self._normalized(uv)
        a, b = x_d.copy(), y_d.copy()
        eps = 1e-7
        for _ in range(_NEWTON_STEPS):
            fx_, fy_ = self._distort(a, b)
            ex, ey = fx_ - x_d, fy_ - y_d
            # The 2x2 Jacobian by central differences: the distortion is a smooth polynomial
            # ratio, and this keeps one formula for both models.
            xa, ya = self._distort(a + eps, b)
            xa2, ya2 = self._distort(a - eps, b)
            xb, yb = self._distort(a, b + eps)
            xb2, yb2 = self._distort(a, b - eps)
            j11, j21 = (xa - xa2) / (2 * eps), (ya - ya2) / (2 * eps)
            j12, j22 = (xb - xb2) / (2 * eps), (yb - yb2) / (2 * eps)
            det = j11 * j22 - j12 * j21
            with np.errstate(divide="ignore", invalid="ignore"):
                da = (j22 * ex - j12 * ey) / det
                db = (-j21 * ex + j11 * ey) / det
            a, b = a - da, b - db
            # Stay on this side of the fold: beyond it the same pixel has a second preimage.
            r = np.hypot(a, b)
            with np.errstate(invalid="ignore", divide="ignore"):
                shrink = np.where(r > self.max_tan, self.max_tan / r, 1.0)
            a, b = a * shrink, b * shrink
            if np.nanmax(np.abs(np.concatenate([da, db])), initial=0.0) < 1e-13:
                break
        optical = np.stack([a, b, np.ones_like(a)], axis=1)
        return normalized(camera_from_optical(optical))


@dataclass(frozen=True)
class FisheyeCamera(_Lens):
    """``equidistant`` (d = k1, k2, k3, k4): OpenCV's fisheye (Kannala-Brandt) model. The angle
    off the optical axis is taken with atan2, so rays beyond 90 degrees from it project too."""

    max_theta: float = field(init=False, repr=False, compare=False)  # edge of the field of view, rad

    distortion_model: ClassVar[str] = "equidistant"

    def __post_init__(self) -> None:
        self._check("equidistant", 4)
        object.__setattr__(self, "max_theta", _first_fold(self._theta_d, math.pi))

    def _theta_d(self, theta: NDArray[np.float64]) -> NDArray[np.float64]:
        k1, k2, k3, k4 = self.d
        t2 = theta * theta
        return theta * (1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))))

    def project_rays(self, rays: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        """(N, 2) pixels of camera-frame rays and whether each is within the field of view."""
        optical = optical_from_camera(rays)
        rho = np.hypot(optical[:, 0], optical[:, 1])
        theta = np.arctan2(rho, optical[:, 2])
        valid = theta < self.max_theta
        with np.errstate(divide="ignore", invalid="ignore"):
            scale = np.where(rho > 1e-15, self._theta_d(theta) / rho, 1.0)  # on the axis: theta_d/rho -> 1/z
        scale = np.where(valid, scale, np.nan)
        return self._pixels(scale * optical[:, 0], scale * optical[:, 1]), valid

    def unproject_pixels(self, uv: ArrayLike) -> NDArray[np.float64]:
        """(N, 3) unit camera-frame rays seen at pixels (u, v): Newton's method on theta_d(theta)."""
        x, y = self._normalized(uv)
        theta_d = np.hypot(x, y)
        theta = np.minimum(theta_d, self.max_theta)
        k1, k2, k3, k4 = self.d
        for _ in range(_NEWTON_STEPS):
            t2 = theta * theta
            f = self._theta_d(theta) - theta_d
            df = 1.0 + t2 * (3.0 * k1 + t2 * (5.0 * k2 + t2 * (7.0 * k3 + t2 * 9.0 * k4)))
            step = f / df
            theta = np.clip(theta - step, 0.0, self.max_theta)
            if np.nanmax(np.abs(step), initial=0.0) < 1e-14:
                break
        phi = np.arctan2(y, x)
        s = np.sin(theta)
        optical = np.stack([s * np.cos(phi), s * np.sin(phi), np.cos(theta)], axis=1)
        return camera_from_optical(optical)
