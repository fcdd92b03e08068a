"""The region value: area, containment in its own frame, the polygon and the overlap test."""

import math

import numpy as np
import pytest

from swarm_logic.families.roy.regions.shapes import Ellipse


def test_area_and_polygon():
    e = Ellipse(1.0, 2.0, 3.0, 1.0, 0.5)
    assert e.area == pytest.approx(math.pi * 3.0)
    assert e.polygon().area == pytest.approx(e.area, rel=2e-3)
    assert not e.is_circle and Ellipse.circle(0, 0, 2).is_circle


def test_contains_follows_orientation():
    e = Ellipse(0.0, 0.0, 3.0, 1.0, math.pi / 2)  # the long axis along y
    assert e.contains(np.array([[0.0, 2.9], [0.9, 0.0]])).tolist() == [True, True]
    assert e.contains(np.array([[2.9, 0.0], [0.0, 3.1]])).tolist() == [False, False]
    assert e.contains(np.array([[0.0, 2.9]]), margin=0.2).tolist() == [False]


def test_intersects():
    e = Ellipse(0.0, 0.0, 2.0, 1.0)
    assert e.intersects(Ellipse(3.5, 0.0, 2.0, 1.0))
    assert not e.intersects(Ellipse(4.5, 0.0, 2.0, 1.0))
    assert not e.intersects(Ellipse(0.0, 2.5, 2.0, 1.0))


def test_bad_axes_refused():
    with pytest.raises(ValueError, match="semi-axes"):
        Ellipse(0.0, 0.0, 0.0, 1.0)
    with pytest.raises(ValueError, match="semi-axes"):
        Ellipse(0.0, 0.0, float("nan"), 1.0)
