"""Per-class colour gates in HSV, derived from the catalog colours.

A gate accepts a pixel whose hue lies within a half-width of the class hue and whose
saturation and value exceed floors. Hue and saturation do not change when white light
gets brighter or dimmer, which is what makes the gates hold across lit scenes. Gates are
derived from the catalog (hue of the nominal colour, half-width limited by the nearest
other class so that gates never overlap) and can be overridden per class.
"""

from __future__ import annotations

import colorsys
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from objslam_common.catalog import Catalog
    from objslam_detector.config import ColorConfig

OVERRIDE_KEYS = ("hue_deg", "hue_halfwidth_deg", "min_saturation", "min_value")
# OpenCV's 8-bit "full" HSV stores hue in 0..255 for 0..360 deg.
_HUE_UNITS_PER_DEG = 256.0 / 360.0


@dataclass(frozen=True)
class ColorGate:
    """Accepted HSV region of one class; saturation and value in 0..1."""

    label: str
    hue_deg: float
    hue_halfwidth_deg: float
    min_saturation: float
    min_value: float

    def __post_init__(self) -> None:
        if not 0.0 < self.hue_halfwidth_deg <= 180.0:
            raise ValueError(
                f"class {self.label!r}: hue_halfwidth_deg must be in (0, 180], got {self.hue_halfwidth_deg}"
            )
        for name in ("min_saturation", "min_value"):
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                raise ValueError(f"class {self.label!r}: {name} must be in [0, 1], got {value}")

    def hue_ranges(self) -> list[tuple[int, int]]:
        """Inclusive ranges of 8-bit full-range hue (0..255), split where the gate wraps past 0."""
        if self.hue_halfwidth_deg >= 180.0:
            return [(0, 255)]
        lo = int(np.ceil((self.hue_deg - self.hue_halfwidth_deg) * _HUE_UNITS_PER_DEG))
        hi = int(np.floor((self.hue_deg + self.hue_halfwidth_deg) * _HUE_UNITS_PER_DEG))
        lo, hi = lo % 256, hi % 256
        return [(lo, hi)] if lo <= hi else [(0, hi), (lo, 255)]

    def mask(
        self, hue: NDArray[np.uint8], saturation: NDArray[np.uint8], value: NDArray[np.uint8]
    ) -> NDArray[np.uint8]:
        """255 where the planes of a ``COLOR_*2HSV_FULL`` image pass the gate, else 0."""
        result: NDArray[np.uint8] | None = None
        for h_lo, h_hi in self.hue_ranges():
            part = cv2.inRange(hue, h_lo, h_hi)
            result = part if result is None else cv2.bitwise_or(result, part)
        for plane, floor in ((saturation, self.min_saturation), (value, self.min_value)):
            level = int(np.ceil(floor * 255.0))
            if level > 0:
                result = cv2.bitwise_and(result, cv2.threshold(plane, level - 1, 255, cv2.THRESH_BINARY)[1])
        if result is None:
            raise ValueError(f"colour gate {self.label!r} has no hue range")
        return result


def classify(hsv_full: NDArray[np.uint8], gates: Sequence[ColorGate]) -> NDArray[np.uint8]:
    """Class index per pixel: 0 for none, k + 1 for ``gates[k]`` (a later gate wins where overrides overlap).

    Hue gates that do not overlap (the derived ones never do) make the class a function
    of hue alone: one lookup gives the class, two more its saturation and value floors.
    """
    hue, saturation, value = cv2.split(hsv_full)
    tables = lookup_tables(gates)
    if tables is None:
        index = np.zeros_like(hue)
        for k, gate in enumerate(gates):
            mask = gate.mask(hue, saturation, value)
            cv2.subtract(index, 255, dst=index, mask=mask)  # saturates to 0: overwrite, not add
            cv2.add(index, k + 1, dst=index, mask=mask)
        return index
    by_hue, saturation_floor, value_floor = tables
    index = cv2.LUT(hue, by_hue)
    bright = cv2.compare(value, cv2.LUT(index, value_floor), cv2.CMP_GE)
    coloured = cv2.compare(saturation, cv2.LUT(index, saturation_floor), cv2.CMP_GE)
    return cv2.bitwise_and(index, cv2.bitwise_and(bright, coloured))


def lookup_tables(gates: Sequence[ColorGate]) -> tuple[NDArray[np.uint8], NDArray[np.uint8], NDArray[np.uint8]] | None:
    """(class by 8-bit hue, saturation floor by class, value floor by class), or None when hue gates overlap."""
    by_hue = np.zeros(256, dtype=np.uint8)
    saturation_floor = np.zeros(256, dtype=np.uint8)
    value_floor = np.zeros(256, dtype=np.uint8)
    for k, gate in enumerate(gates, start=1):
        for lo, hi in gate.hue_ranges():
            if by_hue[lo : hi + 1].any():
                return None
            by_hue[lo : hi + 1] = k
        saturation_floor[k] = int(np.ceil(gate.min_saturation * 255.0))
        value_floor[k] = int(np.ceil(gate.min_value * 255.0))
    return by_hue, saturation_floor, value_floor


def hue_saturation_value(color_rgb: Sequence[int]) -> tuple[float, float, float]:
    """Hue in degrees [0, 360), saturation and value in 0..1 of an 8-bit RGB colour."""
    h, s, v = colorsys.rgb_to_hsv(*(c / 255.0 for c in color_rgb))
    return 360.0 * h, s, v


def hue_distance_deg(a_deg: float, b_deg: float) -> float:
    d = abs(a_deg - b_deg) % 360.0
    return min(d, 360.0 - d)


def parse_class_overrides(entries: Iterable[str]) -> dict[str, dict[str, float]]:
    """``['red: hue_halfwidth_deg=12, min_value=0.2']`` -> ``{'red': {...}}``; ValueError names the bad entry."""
    overrides: dict[str, dict[str, float]] = {}
    for entry in entries:
        label, sep, rest = str(entry).partition(":")
        label = label.strip()
        if not sep or not label:
            raise ValueError(f"class override {entry!r}: expected 'LABEL: key=value, ...'")
        values = overrides.setdefault(label, {})
        for item in filter(None, (part.strip() for part in rest.split(","))):
            key, eq, text = item.partition("=")
            key = key.strip()
            if not eq or key not in OVERRIDE_KEYS:
                raise ValueError(f"class override {entry!r}: unknown item {item!r} (keys: {', '.join(OVERRIDE_KEYS)})")
            try:
                values[key] = float(text)
            except ValueError as exc:
                raise ValueError(f"class override {entry!r}: {key} must be a number, got {text.strip()!r}") from exc
    return overrides


def derive_gates(catalog: Catalog, config: ColorConfig) -> tuple[ColorGate, ...]:
    """One gate per catalog class, from its nominal colour, then the configured overrides."""
    hsv = {cls.label: hue_saturation_value(cls.color_rgb) for cls in catalog}
    gates = {}
    for label, (hue, sat, _val) in hsv.items():
        others = [hue_distance_deg(hue, h) for other, (h, s, _v) in hsv.items() if other != label and s > 0]
        halfwidth = config.hue_halfwidth_max_deg
        if others:
            halfwidth = min(halfwidth, config.hue_neighbor_fraction * min(others))
        gates[label] = ColorGate(
            label=label,
            hue_deg=hue,
            hue_halfwidth_deg=max(halfwidth, 1.0),
            min_saturation=max(config.min_saturation, config.min_saturation_fraction * sat),
            min_value=config.min_value,
        )
    for label, values in parse_class_overrides(config.class_overrides).items():
        if label not in gates:
            raise ValueError(f"class override for {label!r}: no such class in the catalog ({', '.join(gates)})")
        changes: dict[str, Any] = dict(values)
        gates[label] = replace(gates[label], **changes)
    return tuple(gates.values())
