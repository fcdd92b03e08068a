"""The session as Foxglove draws it: the recording's scene channels, beside its own topics.

- ``/scene/arena`` (``foxglove.SceneUpdate``, once at the start): the floor, the walls and the static obstacles;
- ``/scene/robots`` (``foxglove.SceneUpdate``, ``session.scene_hz`` times a simulated second): every robot as its body
  (a cylinder or a box) in its LED's colour with an arrow for its heading (grey and translucent once it has failed,
  faint while on board a carrier), the obstacles on a path where they are, and what the media and the studies add
  (``Medium.scene``, ``LoopFunctions.scene``: the radio links coloured by RSSI, a study's particles, targets, regions);
- ``/tf`` (``foxglove.FrameTransforms``, with each ``/scene/robots``): each robot's frame ``rNNN`` in ``world``;
- ``/log`` (``foxglove.Log``): every log record of the robots and the services, and the session's events, as they are
  recorded.

The layout ``docs/foxglove-layout.json`` opens a recording (or the live scene, ``swarm-sitl run --live``) ready to
watch. The core draws no robot in particular: bodies come from the robots' profiles.
"""

from __future__ import annotations

import json
from typing import TYPE_CHECKING, Any

import pybullet as pb

from bridge.core import foxglove as fx

if TYPE_CHECKING:
    from bridge.core.hub import Hub

WALL_RGBA = fx.color(0.55, 0.55, 0.6, 1.0)
OBSTACLE_RGBA = fx.color(0.45, 0.35, 0.25, 1.0)
FLOOR_RGBA = fx.color(0.92, 0.92, 0.9, 1.0)
DEAD_RGBA = fx.color(0.4, 0.4, 0.4, 0.35)
LED_OFF_RGBA = fx.color(0.2, 0.2, 0.22, 1.0)


class Scene:
    """Writes the scene channels of one session's recording (and hands every message to ``live``, if any)."""

    def __init__(self, hub: Hub, live: Any = None) -> None:
        self.hub = hub
        self.live = live
        q = hub.q_ns
        self.every = max(1, round(1e9 / hub.cfg.session.scene_hz / q))  # quanta between scene updates
        self.started = False

    def write(self, t: int, topic: str, schema: str, msg: dict[str, Any]) -> None:
        self.hub.rec.write(t, topic, schema, msg)
        if self.live is not None:
            self.live.log(topic, schema, msg, t)

    def tick(self, t: int) -> None:
        """At the start of quantum ``t`` (poses as physics left them at ``t``)."""
        if not self.started:
            self.started = True
            self.write(t, "/scene/arena", fx.SCENE_UPDATE, fx.scene_update(t, self._arena(t)))
        if self.hub.k % self.every == 0:
            self.write(t, "/scene/robots", fx.SCENE_UPDATE, fx.scene_update(t, self._robots(t)))
            self.write(t, "/tf", fx.FRAME_TRANSFORMS, self._transforms(t))

    def log(self, t: int, source: str, topic: str, values: dict[str, Any], level: int = fx.LOG_INFO) -> None:
        """A log record, as ``foxglove.Log`` on ``/log``."""
        self.write(t, "/log", fx.LOG, fx.log(t, f"{source}/{topic}", json.dumps(values, sort_keys=True,
                                                                               separators=(",", ":")), level))

    # -- what is drawn ------------------------------------------------------------------------------------------
    def _arena(self, t: int) -> list[dict[str, Any]]:
        w = self.hub.world
        a = self.hub.cfg.arena
        out = [fx.entity(t, "floor", cubes=[fx.shape(a.width_m / 2, a.length_m / 2, -0.005,
                                                      (a.width_m, a.length_m, 0.01), FLOOR_RGBA)])]
        for i, (cx, cy, sx, sy, yaw, h) in enumerate(w.scenery_boxes):
            rgba = WALL_RGBA if i < 4 else OBSTACLE_RGBA  # the arena's four walls come first
            out.append(fx.entity(t, f"static/box{i}", cubes=[fx.shape(cx, cy, h / 2, (sx, sy, h), rgba, yaw)]))
        for i, (x, y, r, h) in enumerate(w.scenery_cylinders):
            out.append(fx.entity(t, f"static/cylinder{i}", cylinders=[fx.shape(x, y, h / 2, (2 * r, 2 * r, h),
                                                                                OBSTACLE_RGBA)]))
        return out

    def _robots(self, t: int) -> list[dict[str, Any]]:
        hub = self.hub
        w = hub.world
        out = []
        for r, rp in enumerate(hub.plan.robots):
            prof = w.profiles[r]
            x, y, yaw = float(w.pos[r, 0]), float(w.pos[r, 1]), float(w.yaw[r])
            name = f"r{r:03d}"
            if rp.gateway is not None:  # a radio's antenna, not a body
                out.append(fx.entity(t, name, metadata={"kind": "xbee_gateway"}, spheres=[
                    fx.shape(x, y, prof.height_m, (0.08, 0.08, 0.08), fx.color(0.2, 0.4, 0.9))]))
                continue
            led = [int(v) for v in w.led[r]]
            alive = bool(w.alive[r])
            rgba = (DEAD_RGBA if not alive else fx.color(*(v / 255 for v in led)) if any(led) else LED_OFF_RGBA)
            if r in w.carried:
                rgba = {**rgba, "a": 0.3}
            h = prof.height_m
            body = (fx.shape(x, y, h / 2, (prof.length_m, prof.width_m, h), rgba, yaw) if prof.is_box else
                    fx.shape(x, y, h / 2, (2 * prof.radius_m, 2 * prof.radius_m, h), rgba, yaw))
            reach = prof.length_m / 2 if prof.is_box else prof.radius_m
            meta = {"profile": rp.profile, "alive": str(alive).lower(), "led": ",".join(map(str, led)),
                    "battery_v": f"{float(w.battery_v[r]):.2f}"}
            out.append(fx.entity(t, name, metadata=meta,
                                 **{"cubes" if prof.is_box else "cylinders": [body]},
                                 arrows=[fx.arrow(x, y, h + 0.01, yaw, max(0.1, 1.6 * reach),
                                                  fx.color(0.1, 0.1, 0.1, 0.9 if alive else 0.3))],
                                 texts=[fx.text(x, y, h + 0.12, str(r), fx.color(0.1, 0.1, 0.1))]))
        for i, (body, _, _, half) in enumerate(w.movers):
            pos, orn = pb.getBasePositionAndOrientation(body, physicsClientId=w.cid)
            yaw = pb.getEulerFromQuaternion(orn)[2]
            sx, sy, sz = w.scenery_movers[i]
            prim = ({"cylinders": [fx.shape(pos[0], pos[1], half, (sx, sy, sz), OBSTACLE_RGBA)]} if sx == sy and
                    w.scenery_mover_round[i] else
                    {"cubes": [fx.shape(pos[0], pos[1], half, (sx, sy, sz), OBSTACLE_RGBA, yaw)]})
            out.append(fx.entity(t, f"mover{i}", **prim))
        for part in [*hub._media, *hub.loop_functions]:
            out += part.scene(t)
        return out

    def _transforms(self, t: int) -> dict[str, Any]:
        w = self.hub.world
        ts = fx.stamp(t)
        return {"transforms": [
            {"timestamp": ts, "parent_frame_id": fx.WORLD_FRAME, "child_frame_id": f"r{r:03d}",
             "translation": {"x": round(float(w.pos[r, 0]), 5), "y": round(float(w.pos[r, 1]), 5), "z": 0.0},
             "rotation": fx.yaw_rotation(float(w.yaw[r]))}
            for r in range(self.hub.n)]}
