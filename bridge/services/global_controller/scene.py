"""Regions as a 3D scene a viewer draws: Foxglove's ``foxglove.SceneUpdate`` message (JSON encoding), recorded by a
service with ``Service.log(topic, scene, SCENE_SCHEMA)``. Each update first deletes the topic's earlier entities,
then gives one entity per region (``region/<group>``): its outline as a closed line (an ellipse sampled at
``Ellipse.boundary``'s vertices, a polygon's vertices), in metres on the floor, coloured by group.

The schema and the builders are the recording's Foxglove ones (``bridge.core.foxglove``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from bridge.core import foxglove as fx

SCENE_SCHEMA = fx.SCENE_UPDATE
PALETTE = ((0.12, 0.47, 0.71), (1.0, 0.5, 0.05), (0.17, 0.63, 0.17), (0.84, 0.15, 0.16), (0.58, 0.4, 0.74))


def outline(region: Any) -> np.ndarray:
    """A ``planner.Region``'s outline (K, 2), in its own units."""
    if region.ellipse is not None:
        return np.asarray(region.ellipse.boundary(), float)
    return np.asarray(region.vertices, float).reshape(-1, 2)


def region_scene(t_ns: int, regions: Any, unit_m: float, z_m: float = 0.01, thickness_m: float = 0.01) -> dict:
    """A ``foxglove.SceneUpdate`` replacing the topic's entities by ``regions`` (``planner.Region``s in thesis units
    of ``unit_m`` m), drawn as closed lines ``z_m`` above the floor."""
    entities = []
    for region in regions:
        pts = outline(region) * unit_m
        outline_line = fx.line([(float(x), float(y), z_m) for x, y in pts],
                               fx.color(*PALETTE[int(region.group) % len(PALETTE)]), fx.LINE_LOOP, thickness_m)
        d = region.as_dict()
        entities.append(fx.entity(t_ns, f"region/{region.group}", metadata={"kind": d["kind"],
                                                                             "area": f"{d['area']:.4g}"},
                                  lines=[outline_line]))
    return fx.scene_update(t_ns, entities)
