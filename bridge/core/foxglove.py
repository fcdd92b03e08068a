"""Foxglove's well-known message schemas as the recording writes them (JSON encoding, JSON Schema), and builders for
the primitives a scene is drawn with.

Foxglove draws a channel in its 3D, Log and Transform panels when the channel's schema has the well-known name
(``foxglove.SceneUpdate``, ``foxglove.FrameTransforms``, ``foxglove.Log``) and its messages have that schema's fields;
the JSON Schemas registered here describe the fields written (the full schemas have more, which a viewer treats as
empty). One place for them: the session's scene (``bridge.core.scene``), a global controller's regions and a study's
own entities all build with these.
"""

from __future__ import annotations

import math
from typing import Any

from bridge.core.recorder import register_schema

SCENE_UPDATE = "foxglove.SceneUpdate"
FRAME_TRANSFORMS = "foxglove.FrameTransforms"
LOG = "foxglove.Log"
WORLD_FRAME = "world"
PRIMITIVES = ("arrows", "cubes", "spheres", "cylinders", "lines", "triangles", "texts", "models")
LINE_STRIP, LINE_LOOP, LINE_LIST = 0, 1, 2  # foxglove.LinePrimitive types
DELETE_MATCHING_ID, DELETE_ALL = 0, 1  # foxglove.SceneEntityDeletion types
LOG_INFO, LOG_WARNING, LOG_ERROR = 2, 3, 4  # foxglove.Log levels

_TIME = {"type": "object", "properties": {"sec": {"type": "integer", "minimum": 0},
                                          "nsec": {"type": "integer", "minimum": 0}}}
_VEC = {"type": "object", "properties": {k: {"type": "number"} for k in "xyz"}}
_QUAT = {"type": "object", "properties": {k: {"type": "number"} for k in "xyzw"}}
_POSE = {"type": "object", "properties": {"position": _VEC, "orientation": _QUAT}}
_COLOR = {"type": "object", "properties": {k: {"type": "number"} for k in "rgba"}}
_SHAPE = {"type": "object", "properties": {"pose": _POSE, "size": _VEC, "color": _COLOR}}
_LINE = {
    "title": "foxglove.LinePrimitive",
    "type": "object",
    "properties": {
        "type": {"type": "integer", "description": "0 line strip, 1 line loop, 2 line list"},
        "pose": _POSE,
        "thickness": {"type": "number"},
        "scale_invariant": {"type": "boolean"},
        "points": {"type": "array", "items": _VEC},
        "color": _COLOR,
        "colors": {"type": "array", "items": _COLOR},
        "indices": {"type": "array", "items": {"type": "integer"}},
    },
}
_ITEMS = {
    "cubes": {"title": "foxglove.CubePrimitive", **_SHAPE},
    "spheres": {"title": "foxglove.SpherePrimitive", **_SHAPE},
    "cylinders": {"title": "foxglove.CylinderPrimitive", "type": "object",
                  "properties": {**_SHAPE["properties"], "bottom_scale": {"type": "number"},
                                 "top_scale": {"type": "number"}}},
    "arrows": {"title": "foxglove.ArrowPrimitive", "type": "object",
               "properties": {"pose": _POSE, "shaft_length": {"type": "number"}, "shaft_diameter": {"type": "number"},
                              "head_length": {"type": "number"}, "head_diameter": {"type": "number"},
                              "color": _COLOR}},
    "texts": {"title": "foxglove.TextPrimitive", "type": "object",
              "properties": {"pose": _POSE, "billboard": {"type": "boolean"}, "font_size": {"type": "number"},
                             "scale_invariant": {"type": "boolean"}, "color": _COLOR, "text": {"type": "string"}}},
    "lines": _LINE,
}

register_schema(SCENE_UPDATE, {
    "title": SCENE_UPDATE,
    "description": "An update to the entities displayed in a 3D scene",
    "type": "object",
    "properties": {
        "deletions": {"type": "array", "items": {
            "title": "foxglove.SceneEntityDeletion", "type": "object",
            "properties": {"timestamp": _TIME, "type": {"type": "integer"}, "id": {"type": "string"}}}},
        "entities": {"type": "array", "items": {
            "title": "foxglove.SceneEntity", "type": "object",
            "properties": {
                "timestamp": _TIME, "frame_id": {"type": "string"}, "id": {"type": "string"}, "lifetime": _TIME,
                "frame_locked": {"type": "boolean"},
                "metadata": {"type": "array", "items": {"type": "object", "properties": {
                    "key": {"type": "string"}, "value": {"type": "string"}}}},
                **{p: {"type": "array", "items": _ITEMS.get(p, {"type": "object"})} for p in PRIMITIVES},
            }}},
    },
})
register_schema(FRAME_TRANSFORMS, {
    "title": FRAME_TRANSFORMS,
    "description": "Transforms between coordinate frames (each robot's frame in the world's)",
    "type": "object",
    "properties": {"transforms": {"type": "array", "items": {
        "title": "foxglove.FrameTransform", "type": "object",
        "properties": {"timestamp": _TIME, "parent_frame_id": {"type": "string"},
                       "child_frame_id": {"type": "string"}, "translation": _VEC, "rotation": _QUAT}}}},
})
register_schema(LOG, {
    "title": LOG,
    "description": "A log message (a robot's or a service's log record, a session event)",
    "type": "object",
    "properties": {"timestamp": _TIME, "level": {"type": "integer", "description": "1 debug, 2 info, 3 warning, "
                                                                                   "4 error, 5 fatal"},
                   "message": {"type": "string"}, "name": {"type": "string"}, "file": {"type": "string"},
                   "line": {"type": "integer"}},
})


def stamp(t_ns: int) -> dict[str, int]:
    """A Foxglove time."""
    return {"sec": t_ns // 1_000_000_000, "nsec": t_ns % 1_000_000_000}


def color(r: float, g: float, b: float, a: float = 1.0) -> dict[str, float]:
    return {"r": round(r, 4), "g": round(g, 4), "b": round(b, 4), "a": round(a, 4)}


def yaw_rotation(yaw: float) -> dict[str, float]:
    """The quaternion of a rotation by ``yaw`` (rad) about the vertical."""
    return {"x": 0.0, "y": 0.0, "z": round(math.sin(yaw / 2), 6), "w": round(math.cos(yaw / 2), 6)}


def pose(x: float = 0.0, y: float = 0.0, z: float = 0.0, yaw: float = 0.0) -> dict[str, Any]:
    """A pose on the floor: a position and a rotation about the vertical."""
    return {"position": {"x": round(x, 5), "y": round(y, 5), "z": round(z, 5)}, "orientation": yaw_rotation(yaw)}


def shape(x: float, y: float, z: float, size: tuple[float, float, float], rgba: dict[str, float],
          yaw: float = 0.0) -> dict[str, Any]:
    """A cube or a cylinder (or sphere) centred at (x, y, z), of ``size`` (m along x, y, z)."""
    sx, sy, sz = size
    return {"pose": pose(x, y, z, yaw), "size": {"x": round(sx, 5), "y": round(sy, 5), "z": round(sz, 5)},
            "color": rgba}


def line(points: list[tuple[float, float, float]], rgba: dict[str, float], kind: int = LINE_STRIP,
         thickness_m: float = 0.02, colors: list[dict[str, float]] | None = None) -> dict[str, Any]:
    """A line through ``points`` (world frame, m); ``colors``: one per point (a line list's segments by their ends)."""
    return {"type": kind, "pose": pose(), "thickness": thickness_m, "scale_invariant": False,
            "points": [{"x": round(x, 5), "y": round(y, 5), "z": round(z, 5)} for x, y, z in points],
            "color": rgba, "colors": colors or [], "indices": []}


def arrow(x: float, y: float, z: float, yaw: float, length_m: float, rgba: dict[str, float]) -> dict[str, Any]:
    return {"pose": pose(x, y, z, yaw), "shaft_length": round(0.7 * length_m, 5),
            "shaft_diameter": round(0.12 * length_m, 5), "head_length": round(0.3 * length_m, 5),
            "head_diameter": round(0.25 * length_m, 5), "color": rgba}


def text(x: float, y: float, z: float, words: str, rgba: dict[str, float], size: float = 12.0) -> dict[str, Any]:
    return {"pose": pose(x, y, z), "billboard": True, "font_size": size, "scale_invariant": True, "color": rgba,
            "text": words}


def entity(t_ns: int, ident: str, frame: str = WORLD_FRAME, metadata: dict[str, str] | None = None,
           **primitives: list[dict[str, Any]]) -> dict[str, Any]:
    """A scene entity (no lifetime: it stays until an update deletes or replaces it) with its primitives by kind."""
    unknown = set(primitives) - set(PRIMITIVES)
    if unknown:
        raise ValueError(f"not Foxglove primitives: {sorted(unknown)}")
    return {"timestamp": stamp(t_ns), "frame_id": frame, "id": ident, "lifetime": {"sec": 0, "nsec": 0},
            "frame_locked": False, "metadata": [{"key": k, "value": v} for k, v in (metadata or {}).items()],
            **{p: primitives.get(p, []) for p in PRIMITIVES}}


def scene_update(t_ns: int, entities: list[dict[str, Any]], replace: bool = True) -> dict[str, Any]:
    """A ``foxglove.SceneUpdate``: ``entities``, after deleting the topic's earlier ones if ``replace``."""
    deletions = [{"timestamp": stamp(t_ns), "type": DELETE_ALL, "id": ""}] if replace else []
    return {"deletions": deletions, "entities": entities}


def log(t_ns: int, name: str, message: str, level: int = LOG_INFO) -> dict[str, Any]:
    """A ``foxglove.Log`` message from ``name`` (``r003/neighbours``)."""
    return {"timestamp": stamp(t_ns), "level": level, "message": message, "name": name, "file": "", "line": 0}


def rssi_colour(rssi_dbm: float, lo: float = -95.0, hi: float = -45.0) -> dict[str, float]:
    """A link's colour by its RSSI: red at ``lo`` dBm and below, through yellow, to green at ``hi`` and above."""
    u = min(1.0, max(0.0, (rssi_dbm - lo) / (hi - lo)))
    return color(min(1.0, 2 * (1 - u)), min(1.0, 2 * u), 0.1, 0.9)
