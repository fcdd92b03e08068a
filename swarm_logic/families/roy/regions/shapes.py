"""The regions' shapes: the ellipse of chapters 4 and 6 (a circle when a = b), as a value the planners pass around,
broadcast and record, and as a shapely polygon where the planners need set operations (intersection, erosion).

The axes are semi-axes (digest 001 §2.2.8: the thesis' area pi a b, confirmed by its hardware figures); ``a`` lies
along ``theta``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from shapely.geometry import Polygon

POLYGON_VERTICES = 72  # an ellipse as a polygon: area within 0.13 % of pi a b


@dataclass(frozen=True)
class Ellipse:
    """A region: centre (x, y), semi-axes ``a`` (along ``theta``) and ``b``, orientation ``theta`` (rad)."""

    x: float
    y: float
    a: float
    b: float
    theta: float = 0.0

    def __post_init__(self) -> None:
        if not (self.a > 0 and self.b > 0 and math.isfinite(self.a) and math.isfinite(self.b)):
            raise ValueError(f"an ellipse needs finite semi-axes > 0, got a = {self.a}, b = {self.b}")

    @classmethod
    def circle(cls, x: float, y: float, r: float) -> Ellipse:
        return cls(x, y, r, r, 0.0)

    @property
    def centre(self) -> np.ndarray:
        return np.array([self.x, self.y])

    @property
    def area(self) -> float:
        return math.pi * self.a * self.b

    @property
    def is_circle(self) -> bool:
        return math.isclose(self.a, self.b, rel_tol=1e-9)

    def moved(self, x: float, y: float) -> Ellipse:
        return replace(self, x=x, y=y)

    def local(self, points: np.ndarray) -> np.ndarray:
        """``points`` (..., 2) in the ellipse's frame: along the a axis, then along the b axis."""
        c, s = math.cos(self.theta), math.sin(self.theta)
        d = np.asarray(points, dtype=float) - self.centre
        return np.stack([d[..., 0] * c + d[..., 1] * s, -d[..., 0] * s + d[..., 1] * c], axis=-1)

    def level(self, points: np.ndarray) -> np.ndarray:
        """(u / a)^2 + (v / b)^2 of each point: <= 1 inside."""
        q = self.local(points)
        return (q[..., 0] / self.a) ** 2 + (q[..., 1] / self.b) ** 2

    def contains(self, points: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """Whether each point lies inside the ellipse shrunk by ``margin`` on both semi-axes (a point of an agent of
        radius ``margin`` whose body is inside)."""
        q = self.local(points)
        a, b = max(self.a - margin, 1e-12), max(self.b - margin, 1e-12)
        return (q[..., 0] / a) ** 2 + (q[..., 1] / b) ** 2 <= 1.0

    def boundary(self, n: int = POLYGON_VERTICES) -> np.ndarray:
        """``n`` points on the boundary, counter-clockwise, (n, 2)."""
        t = np.linspace(0.0, 2 * math.pi, n, endpoint=False)
        c, s = math.cos(self.theta), math.sin(self.theta)
        u, v = self.a * np.cos(t), self.b * np.sin(t)
        return np.stack([self.x + u * c - v * s, self.y + u * s + v * c], axis=1)

    def polygon(self, n: int = POLYGON_VERTICES) -> Polygon:
        return Polygon(self.boundary(n))

    def intersects(self, other: Ellipse) -> bool:
        """Whether the two regions overlap with an area > 0 (chapter 6's merge trigger)."""
        return self.polygon().intersection(other.polygon()).area > 0.0

    def as_dict(self) -> dict[str, float]:
        return {"x": self.x, "y": self.y, "a": self.a, "b": self.b, "theta": self.theta}
