"""The class catalog: what each object class looks like and where it stands.

Each class carries its nominal colour (for the detector), its nominal size and base
height, and the Gaussian priors of the model built from them (paper eqs. 7-8):
size ``g ~ N(zeta(c), Sigma(c))`` and location ``l ~ N(gamma(c), Gamma(c))``, where the
location prior is weak in x, y and tight in z_base.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from objslam_common.config import default_config_dir, read_yaml
from objslam_common.errors import ConfigError


@dataclass(frozen=True)
class ObjectClass:
    """One class of the catalog; sizes and heights in metres."""

    label: str
    color_rgb: tuple[int, int, int]
    diameter_m: float
    height_m: float
    z_base_m: float
    diameter_stddev_m: float
    height_stddev_m: float
    z_base_stddev_m: float
    xy_stddev_m: float

    @property
    def size_mean(self) -> NDArray[np.float64]:
        """zeta(c): (diameter, height), m."""
        return np.array([self.diameter_m, self.height_m])

    @property
    def size_covariance(self) -> NDArray[np.float64]:
        """Sigma(c), m^2."""
        return np.diag([self.diameter_stddev_m**2, self.height_stddev_m**2])

    @property
    def z_base_variance(self) -> float:
        return self.z_base_stddev_m**2

    @property
    def on_floor(self) -> bool:
        return abs(self.z_base_m) < 1e-9


@dataclass(frozen=True)
class Catalog:
    """The classes by label, in file order."""

    classes: tuple[ObjectClass, ...]

    def __post_init__(self) -> None:
        labels = [c.label for c in self.classes]
        if len(set(labels)) != len(labels):
            raise ConfigError(f"duplicate class labels in catalog: {labels}")

    @property
    def labels(self) -> tuple[str, ...]:
        return tuple(c.label for c in self.classes)

    def __getitem__(self, label: str) -> ObjectClass:
        for cls in self.classes:
            if cls.label == label:
                return cls
        raise KeyError(f"unknown class label {label!r} (catalog has {', '.join(self.labels)})")

    def __contains__(self, label: object) -> bool:
        return any(c.label == label for c in self.classes)

    def __iter__(self):
        return iter(self.classes)

    def __len__(self) -> int:
        return len(self.classes)


def default_catalog_path() -> Path:
    return default_config_dir() / "catalog.yaml"


def load_catalog(path: str | os.PathLike[str] | None = None) -> Catalog:
    """Read a catalog file (default: the bundled ``config/catalog.yaml``)."""
    path = Path(path) if path else default_catalog_path()
    data = read_yaml(path)
    if not isinstance(data, dict) or not isinstance(data.get("classes"), dict) or not data["classes"]:
        raise ConfigError(f"{path}: expected a mapping 'classes' of label -> class")
    defaults = data.get("defaults", {}) or {}
    rel = float(defaults.get("size_relative_stddev", 0.06))
    floor_z_sd = float(defaults.get("floor_z_base_stddev_m", 0.01))
    raised_z_sd = float(defaults.get("raised_z_base_stddev_m", 0.05))
    xy_sd = float(defaults.get("xy_stddev_m", 100.0))
    classes = []
    for label, spec in data["classes"].items():
        try:
            rgb = tuple(int(v) for v in spec["color_rgb"])
            if len(rgb) != 3 or not all(0 <= v <= 255 for v in rgb):
                raise ValueError("color_rgb must be three values in 0..255")
            diameter = float(spec["diameter_m"])
            height = float(spec["height_m"])
            z_base = float(spec.get("z_base_m", 0.0))
            if diameter <= 0 or height <= 0 or z_base < 0:
                raise ValueError("diameter_m and height_m must be > 0, z_base_m >= 0")
            cls = ObjectClass(
                label=str(label),
                color_rgb=(rgb[0], rgb[1], rgb[2]),
                diameter_m=diameter,
                height_m=height,
                z_base_m=z_base,
                diameter_stddev_m=float(spec.get("diameter_stddev_m", rel * diameter)),
                height_stddev_m=float(spec.get("height_stddev_m", rel * height)),
                z_base_stddev_m=float(spec.get("z_base_stddev_m", floor_z_sd if z_base == 0 else raised_z_sd)),
                xy_stddev_m=float(spec.get("xy_stddev_m", xy_sd)),
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise ConfigError(f"{path}: class {label!r}: {exc}") from exc
        classes.append(cls)
    return Catalog(tuple(classes))
