"""Regions as a 3D scene a viewer draws: Foxglove's ``foxglove.SceneUpdate`` message (JSON encoding), recorded by a
service with ``Service.log(topic, scene, SCENE_SCHEMA)``. Each update first deletes the topic's earlier entities,
then gives one entity per region (``region/<group>``): its outline as a closed line (an ellipse sampled at
``Ellipse.boundary``'s vertices, a polygon's vertices), in metres on the floor, coloured by group.

The schema registered here (with the recorder, in whichever process imports this module: the world does, through
the global controller's kind) describes the fields written; the full Foxglove schema has more primitives, which a
viewer treats as empty.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from bridge.core.recorder import register_schema

SCENE_SCHEMA = "foxglove.SceneUpdate"
FRAME = "world"
PRIMITIVES = ("arrows", "cubes", "spheres", "cylinders", "lines", "triangles", "texts", "models")
LINE_LOOP = 1  # foxglove.LinePrimitive type: the last point joins the first
DELETE_ALL = 1  # foxglove.SceneEntityDeletion type: every entity on the topic
PALETTE = ((0.12, 0.47, 0.71), (1.0, 0.5, 0.05), (0.17, 0.63, 0.17), (0.84, 0.15, 0.16), (0.58, 0.4, 0.74))

_TIME = {
    "type": "object",
    "properties": {"sec": {"type": "integer", "minimum": 0}, "nsec": {"type": "integer", "minimum": 0}},
}
_VEC = {"type": "object", "properties": {k: {"type": "number"} for k in "xyz"}}
_COLOR = {"type": "object", "properties": {k: {"type": "number"} for k in "rgba"}}
_LINE = {
    "title": "foxglove.LinePrimitive",
    "type": "object",
    "properties": {
        "type": {"type": "integer", "description": "0 line strip, 1 line loop, 2 line list"},
        "pose": {
            "type": "object",
            "properties": {"position": _VEC, "orientation": {"type": "object"}},
        },
        "thickness": {"type": "number"},
        "scale_invariant": {"type": "boolean"},
        "points": {"type": "array", "items": _VEC},
        "color": _COLOR,
        "colors": {"type": "array", "items": _COLOR},
        "indices": {"type": "array", "items": {"type": "integer"}},
    },
}
register_schema(
    SCENE_SCHEMA,
    {
        "title": SCENE_SCHEMA,
        "description": "An update to the entities displayed in a 3D scene (the regions a global controller planned)",
        "type": "object",
        "properties": {
            "deletions": {
                "type": "array",
                "items": {
                    "type": "object",
                    "properties": {"timestamp": _TIME, "type": {"type": "integer"}, "id": {"type": "string"}},
                },
            },
            "entities": {
                "type": "array",
                "items": {
                    "title": "foxglove.SceneEntity",
                    "type": "object",
                    "properties": {
                        "timestamp": _TIME,
                        "frame_id": {"type": "string"},
                        "id": {"type": "string"},
                        "lifetime": _TIME,
                        "frame_locked": {"type": "boolean"},
                        "metadata": {
                            "type": "array",
                            "items": {
                                "type": "object",
                                "properties": {"key": {"type": "string"}, "value": {"type": "string"}},
                            },
                        },
                        **{
                            p: {"type": "array", "items": _LINE if p == "lines" else {"type": "object"}}
                            for p in PRIMITIVES
                        },
                    },
                },
            },
        },
    },
)


def _time(t_ns: int) -> dict[str, int]:
    return {"sec": t_ns // 1_000_000_000, "nsec": t_ns % 1_000_000_000}


def outline(region: Any) -> np.ndarray:
    """A ``planner.Region``'s outline (K, 2), in its own units."""
    if region.ellipse is not None:
        return np.asarray(region.ellipse.boundary(), float)
    return np.asarray(region.vertices, float).reshape(-1, 2)


def region_scene(t_ns: int, regions: Any, unit_m: float, z_m: float = 0.01, thickness_m: float = 0.01) -> dict:
    """A ``foxglove.SceneUpdate`` replacing the topic's entities by ``regions`` (``planner.Region``s in thesis units
    of ``unit_m`` m), drawn as closed lines ``z_m`` above the floor."""
    ts = _time(t_ns)
    entities = []
    for region in regions:
        pts = outline(region) * unit_m
        r, g, b = PALETTE[int(region.group) % len(PALETTE)]
        line = {
            "type": LINE_LOOP,
            "pose": {
                "position": {"x": 0.0, "y": 0.0, "z": 0.0},
                "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
            },
            "thickness": thickness_m,
            "scale_invariant": False,
            "points": [{"x": round(float(x), 5), "y": round(float(y), 5), "z": z_m} for x, y in pts],
            "color": {"r": r, "g": g, "b": b, "a": 1.0},
            "colors": [],
            "indices": [],
        }
        d = region.as_dict()
        entities.append(
            {
                "timestamp": ts,
                "frame_id": FRAME,
                "id": f"region/{region.group}",
                "lifetime": {"sec": 0, "nsec": 0},
                "frame_locked": False,
                "metadata": [{"key": "kind", "value": d["kind"]}, {"key": "area", "value": f"{d['area']:.4g}"}],
                **{p: [line] if p == "lines" else [] for p in PRIMITIVES},
            }
        )
    return {"deletions": [{"timestamp": ts, "type": DELETE_ALL, "id": ""}], "entities": entities}
