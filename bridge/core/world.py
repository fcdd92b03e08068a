"""The physical world: one pybullet DIRECT client with the arena, obstacles, light field and robots.

Each robot is one rigid cylinder (or box) of its profile's size and mass; what moves it and what it senses are its parts
(``bridge.core.parts``: a differential drive, sonars, a conveyor, ... from the robot's plugin), each simulated by one
world model for every robot that has it. The world keeps what every robot has: its pose, whether it is alive, its
LEDs, its battery, a stated motion for bodies the session does not drive, and robots riding on board another.

Nothing here reads the wall clock or an unseeded random source; pybullet's banner goes to stdout, which
is never parsed.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pybullet as pb

from bridge.core.arena_map import occupancy
from bridge.core.config import ArenaCfg, BoxObstacle, Config
from bridge.core.faults import SensorFaults
from bridge.core.parts import WorldModel
from bridge.core.plan import RobotPlan
from bridge.core.profile import RobotProfile
from bridge.core.registry import robot_profile
from swarm_logic.geometry import wrap

# Li-ion open-circuit voltage per cell against state of charge (typical curve).
_OCV_SOC = np.array([0.0, 0.05, 0.1, 0.2, 0.4, 0.6, 0.8, 0.9, 1.0])
_OCV_V = np.array([3.0, 3.45, 3.6, 3.68, 3.76, 3.86, 4.0, 4.08, 4.2])


class World:
    def __init__(self, cfg: Config, robots: list[RobotPlan]) -> None:
        self.cfg = cfg
        self.seed = cfg.session.seed
        self.profiles: list[RobotProfile] = [robot_profile(r.profile, r.options) for r in robots]
        # the session's physics rate, or a finer one that a robot's part asks for (a body on jointed legs)
        self.hz = max([cfg.world.physics_hz, *(p.physics_hz for prof in self.profiles for p in prof.parts)])
        self.dt = 1.0 / self.hz
        self.steps_done = 0
        self.cid = pb.connect(pb.DIRECT)
        c = self.cid
        pb.setGravity(0, 0, -9.81, physicsClientId=c)
        pb.setTimeStep(self.dt, physicsClientId=c)
        pb.setPhysicsEngineParameter(numSolverIterations=cfg.world.solver_iterations, physicsClientId=c)
        plane = pb.createCollisionShape(pb.GEOM_PLANE, physicsClientId=c)
        pb.createMultiBody(0, plane, physicsClientId=c)
        # The walls scene: a second client holding only the static bodies (the floor, walls, obstacles), where the
        # radio's wall rays are cast. They count static bodies only, so the answer is the same as in the full scene,
        # but a ray there does not wade through the robots' moving bodies (five times faster at 50 robots).
        self.walls_cid = pb.connect(pb.DIRECT)
        pb.createMultiBody(0, pb.createCollisionShape(pb.GEOM_PLANE, physicsClientId=self.walls_cid),
                           physicsClientId=self.walls_cid)
        self._walls_twins: dict[int, int] = {}  # a static body that moves -> its twin in the walls scene
        self._walls_synced = False
        self._walls_boxed = False  # its bounding boxes computed as a physics step computes them
        self.static_rects: list[tuple[float, float, float, float, float]] = []  # cx, cy, sx, sy, yaw (plots)
        self.cylinders: list[tuple[float, float, float]] = []
        # the same with their heights, for the scene a viewer draws (bridge.core.scene); obstacles on a path: sizes
        self.scenery_boxes: list[tuple[float, float, float, float, float, float]] = []  # cx, cy, sx, sy, yaw, h
        self.scenery_cylinders: list[tuple[float, float, float, float]] = []  # x, y, r, h
        self.scenery_movers: list[tuple[float, float, float]] = []  # each mover's size (x, y, z)
        self.scenery_mover_round: list[bool] = []
        self._build_arena(cfg.arena)
        # obstacles on a stated path (toy cars): (body, path rows (t_s, x, y, yaw), period_s or 0, half height)
        self.movers: list[tuple[int, np.ndarray, float, float]] = []
        for ob in cfg.obstacles:
            moving = ob.motion is not None
            if isinstance(ob, BoxObstacle):
                body = self._box(ob.x, ob.y, ob.size, math.radians(ob.yaw_deg), static=not moving)
                half, yaw = ob.size[2] / 2, math.radians(ob.yaw_deg)
            else:
                body = self._cylinder(ob.x, ob.y, ob.radius, ob.height, static=not moving)
                half, yaw = ob.height / 2, 0.0
            if ob.motion is not None:
                rows = [(0.0, ob.x, ob.y, yaw), *((t, x, y, yaw) for t, x, y in ob.motion.waypoints)]
                period = ob.motion.waypoints[-1][0] if ob.motion.repeat else 0.0
                self.movers.append((body, np.array(rows, dtype=float), period, half))
        if cfg.arena.map:
            self._load_map(cfg.arena)
        self._build_robots(robots)
        # what the light sensors read instead of the light field, when a study installs one (an objective with
        # ``lux(x, y)``)
        self.lux_field: Any = None
        # objects a study puts in the world for robots' parts to sense, by name (food particles for a utility
        # sensor); the world itself does nothing with them
        self.objects: dict[str, Any] = {}

    # -- scene ------------------------------------------------------------------------------------
    def _box(self, x: float, y: float, size: tuple[float, float, float], yaw: float = 0.0, static: bool = True) -> int:
        half = [size[0] / 2, size[1] / 2, size[2] / 2]
        orn = pb.getQuaternionFromEuler([0, 0, yaw])
        body, twin = (pb.createMultiBody(0, pb.createCollisionShape(pb.GEOM_BOX, halfExtents=half, physicsClientId=c),
                                         basePosition=[x, y, half[2]], baseOrientation=orn, physicsClientId=c)
                      for c in (self.cid, self.walls_cid))
        if static:
            self.static_rects.append((x, y, size[0], size[1], yaw))
            self.scenery_boxes.append((x, y, size[0], size[1], yaw, size[2]))
        else:
            self._walls_twins[body] = twin
            self.scenery_movers.append(tuple(size))
            self.scenery_mover_round.append(False)
        return body

    def _cylinder(self, x: float, y: float, r: float, h: float, static: bool = True) -> int:
        body, twin = (pb.createMultiBody(0, pb.createCollisionShape(pb.GEOM_CYLINDER, radius=r, height=h,
                                                                    physicsClientId=c),
                                         basePosition=[x, y, h / 2], physicsClientId=c)
                      for c in (self.cid, self.walls_cid))
        if static:
            self.cylinders.append((x, y, r))
            self.scenery_cylinders.append((x, y, r, h))
        else:
            self._walls_twins[body] = twin
            self.scenery_movers.append((2 * r, 2 * r, h))
            self.scenery_mover_round.append(True)
        return body

    def _build_arena(self, a: ArenaCfg) -> None:
        t, h = a.wall_thickness_m, a.wall_height_m
        w, length = a.width_m, a.length_m
        self._box(w / 2, -t / 2, (w + 2 * t, t, h))
        self._box(w / 2, length + t / 2, (w + 2 * t, t, h))
        self._box(-t / 2, length / 2, (t, length, h))
        self._box(w + t / 2, length / 2, (t, length, h))

    def _load_map(self, a: ArenaCfg) -> None:
        """A monochrome bitmap (dark = obstacle) as merged rectangles; row 0 is the arena's far edge."""
        occ = occupancy(a)
        res = a.map_resolution_m
        rows, _ = occ.shape
        open_runs: dict[tuple[int, int], int] = {}  # (c0, c1) -> first row
        rects: list[tuple[int, int, int, int]] = []
        for r in range(rows + 1):
            runs = set()
            if r < rows:
                line = np.concatenate([[False], occ[r], [False]])
                edges = np.flatnonzero(line[1:] != line[:-1])
                runs = {(int(edges[i]), int(edges[i + 1])) for i in range(0, len(edges), 2)}
            for run in list(open_runs):
                if run not in runs:
                    rects.append((open_runs.pop(run), r, *run))
            for run in runs:
                open_runs.setdefault(run, r)
        for r0, r1, c0, c1 in rects:
            sx, sy = (c1 - c0) * res, (r1 - r0) * res
            cx = (c0 + c1) / 2 * res
            cy = (rows - (r0 + r1) / 2) * res
            self._box(cx, cy, (sx, sy, a.wall_height_m))

    def _build_robots(self, robots: list[RobotPlan]) -> None:
        n = len(robots)
        self.n = n
        self._spawn_bodies(robots)
        self._batteries()
        self.pos = np.array([[r.pose[0], r.pose[1]] for r in robots], dtype=float).reshape(n, 2)
        self.yaw = np.array([r.pose[2] for r in robots], dtype=float)
        self.odometer = np.zeros(n)
        self.alive = np.ones(n, dtype=bool)
        self.led = np.zeros((n, 3), dtype=np.uint8)
        self.drive_speed = np.zeros(n)  # how fast each robot's drive is driving it (m/s), per quantum
        self._walls_rows: dict[int, np.ndarray] = {}
        self._models()

    def _spawn_bodies(self, robots: list[RobotPlan]) -> None:
        """One rigid cylinder or box per robot (a gateway's antenna: a point nothing touches; a body a part makes
        itself: ``WorldModel.build_body``), the stated motions, and the robots that start on board another."""
        self.bodies: list[int] = []
        shapes: dict[str, int] = {}
        for r, prof in zip(robots, self.profiles, strict=True):
            if prof.name not in shapes:
                shapes[prof.name] = (
                    pb.createCollisionShape(pb.GEOM_BOX, halfExtents=[prof.length_m / 2, prof.width_m / 2,
                                                                      prof.height_m / 2], physicsClientId=self.cid)
                    if prof.is_box else
                    pb.createCollisionShape(pb.GEOM_CYLINDER, radius=prof.radius_m, height=prof.height_m,
                                            physicsClientId=self.cid))
            x, y, yaw = r.pose
            if r.gateway is not None:  # a radio's antenna, not a body: nothing collides with it or sees it
                self.bodies.append(pb.createMultiBody(0, -1, basePosition=[x, y, prof.height_m / 2 + 1e-3],
                                                      physicsClientId=self.cid))
                continue
            own = self._part_body(prof, (x, y, yaw))
            if own is not None:
                self.bodies.append(own)
                continue
            body = pb.createMultiBody(
                prof.mass_kg, shapes[prof.name], basePosition=[x, y, prof.height_m / 2 + 1e-3],
                baseOrientation=pb.getQuaternionFromEuler([0, 0, yaw]), physicsClientId=self.cid,
            )
            izz = (prof.mass_kg * (prof.length_m**2 + prof.width_m**2) / 12 if prof.is_box
                   else 0.5 * prof.mass_kg * prof.radius_m**2)
            # A drive imposes the body's twist every step, so the body itself must not rub on the floor; huge
            # roll/pitch inertia keeps it upright when it hits something.
            pb.changeDynamics(body, -1, localInertiaDiagonal=[1e3, 1e3, izz], lateralFriction=0.0,
                              linearDamping=0.0, angularDamping=0.0, physicsClientId=self.cid)
            self.bodies.append(body)
        # bodies whose motion the config states (a real board's or vehicle's robot, a gateway): (t, x, y, yaw) rows
        self.paths = {r.id: _path(r) for r in robots if r.scripted}
        # robots riding on board another (a carrier's conveyor): robot -> (carrier, slot); a part of the carrier's
        # decides when each goes down (``drop_off``)
        self.carried: dict[int, tuple[int, int]] = {r.id: (r.carrier, r.slot) for r in robots if r.carrier is not None}
        self.released: list[dict] = []  # drop-offs since the hub last took them (t_ns, robot, carrier, slot, pose)
        for i in self.carried:  # on board nothing touches them and they touch nothing
            pb.setCollisionFilterGroupMask(self.bodies[i], -1, 0, 0, physicsClientId=self.cid)

    def _part_body(self, prof: RobotProfile, pose: tuple[float, float, float]) -> int | None:
        """The body one of the robot's parts makes itself, None if none does."""
        for part in prof.parts:
            body = type(part).world_model.build_body(self, part, prof, pose)
            if body is not None:
                return body
        return None

    def _batteries(self) -> None:
        p = self.profiles
        self.soc = np.ones(self.n)
        self.cells = np.array([q.battery_cells for q in p], dtype=float)
        self.capacity_as = np.array([q.battery_capacity_mah * 3.6 for q in p])
        self.r_int = np.array([q.battery_internal_ohm for q in p])
        self.i_idle = np.array([q.current_idle_ma for q in p]) / 1000.0
        self.sag_v = np.zeros(self.n)  # a brown-out's sag on each battery (bridge.core.faults)
        self.battery_v = self._battery_voltage(np.zeros(self.n))
        self.sensor_faults = SensorFaults()  # stuck, noisy, dead or biased sensors (bridge.core.faults)

    def _models(self) -> None:
        """One world model per kind of part, for every robot with one, in order of first appearance."""
        members: dict[type[WorldModel], tuple[list[int], list[Any]]] = {}
        for r, prof in enumerate(self.profiles):
            for part in prof.parts:
                ids, parts = members.setdefault(type(part).world_model, ([], []))
                ids.append(r)
                parts.append(part)
        self.models: dict[str, WorldModel] = {}
        for cls, (ids, parts) in members.items():
            self.models[cls.name] = cls(self, ids, parts)
        self._robot_models = [[self.models[type(part).world_model.name] for part in prof.parts]
                              for prof in self.profiles]

    def model(self, name: str) -> Any:
        """The world model of one kind of part (``"differential_drive"``, ``"conveyor"``...), None if no robot of
        the session has that part."""
        return self.models.get(name)

    # -- what every robot has ---------------------------------------------------------------------------
    def set_led(self, robot: int, rgb: tuple[int, int, int]) -> None:
        self.led[robot] = rgb

    def deplete(self, robot: int) -> None:
        """The robot's battery is exhausted (an injected fault): no charge left; ``kill`` stops the rest."""
        self.soc[robot] = 0.0
        self.battery_v[robot] = float(self._battery_voltage(np.zeros(self.n))[robot])

    def kill(self, robot: int) -> None:
        """A dead robot: its parts stop, it stays in the arena as an obstacle."""
        self.alive[robot] = False
        for m in self._robot_models[robot]:
            m.kill(robot)
        self.led[robot] = 0

    def drop_off(self, robot: int, x: float, y: float, yaw: float, t_ns: int) -> None:
        """A carried robot goes down onto the floor at (x, y, yaw), solid again."""
        carrier, slot = self.carried.pop(robot)
        c = self.cid
        pb.resetBasePositionAndOrientation(self.bodies[robot], [x, y, self.profiles[robot].height_m / 2 + 1e-3],
                                           pb.getQuaternionFromEuler([0, 0, yaw]), physicsClientId=c)
        pb.resetBaseVelocity(self.bodies[robot], [0, 0, 0], [0, 0, 0], physicsClientId=c)
        pb.setCollisionFilterGroupMask(self.bodies[robot], -1, 1, -1, physicsClientId=c)
        self.pos[robot] = (x, y)
        self.yaw[robot] = yaw
        self.released.append({"t_ns": t_ns, "robot": robot, "carrier": carrier, "slot": slot,
                              "pose": [round(x, 4), round(y, 4), round(yaw, 4)]})

    # -- stepping -----------------------------------------------------------------------------------
    def _battery_voltage(self, current: np.ndarray) -> np.ndarray:
        ocv = np.interp(self.soc, _OCV_SOC, _OCV_V) * self.cells
        return ocv - current * self.r_int - self.sag_v

    def step_quantum(self, t_ns: int, q_ns: int) -> None:
        """Advance physics from ``t_ns`` to ``t_ns + q_ns`` (whole 1/physics_hz steps, exact on average)."""
        target_steps = int((t_ns + q_ns) * self.hz // 1_000_000_000)
        models = list(self.models.values())
        for m in models:
            m.start_quantum(t_ns, q_ns)
        stepped = False
        while self.steps_done < target_steps:
            for m in models:
                m.before_step()
            pb.stepSimulation(physicsClientId=self.cid)
            for m in models:
                m.after_step()
            self.steps_done += 1
            if self.paths:
                self._follow_paths(self.steps_done / self.hz)
            if self.movers:
                self._move_obstacles(self.steps_done / self.hz)
            if self.carried:
                self._ride()
            stepped = True
        t_end = t_ns + q_ns
        if stepped:
            self._read_poses()
        for m in models:
            m.settle(t_end)
        load = np.zeros(self.n)
        for m in models:
            m.load_a(load)
        current = self.i_idle + load
        self.soc = np.clip(self.soc - current * (q_ns * 1e-9) / self.capacity_as, 0.0, 1.0)
        self.battery_v = self._battery_voltage(current)
        self._walls_rows.clear()
        self._walls_synced = False
        for m in models:
            m.drive_speed(self.drive_speed)
        for m in models:
            m.sample(t_end)

    def _follow_paths(self, t_s: float) -> None:
        """Put every body with a stated motion where its path says at ``t_s``, moving as the path moves (so what
        hits it feels its motion); nothing pushes it off its path."""
        for i, path in self.paths.items():
            self._put(self.bodies[i], path, t_s, self.profiles[i].height_m / 2 + 1e-3)

    def _move_obstacles(self, t_s: float) -> None:
        """Put every moving obstacle where its path says at ``t_s``, moving as the path moves (what it hits feels its
        motion)."""
        for body, path, period, half in self.movers:
            self._put(body, path, (t_s % period) if period else t_s, half)

    def _put(self, body: int, path: np.ndarray, t_s: float, z: float) -> None:
        """A body on a stated path at ``t_s``, its velocity the path's over the next physics step."""
        c = self.cid
        x, y, yaw = path_pose(path, t_s)
        x1, y1, yaw1 = path_pose(path, t_s + self.dt)
        pb.resetBasePositionAndOrientation(body, [x, y, z], pb.getQuaternionFromEuler([0, 0, yaw]), physicsClientId=c)
        pb.resetBaseVelocity(body, [(x1 - x) * self.hz, (y1 - y) * self.hz, 0.0],
                             [0.0, 0.0, wrap(yaw1 - yaw) * self.hz], physicsClientId=c)

    def _ride(self) -> None:
        """Robots on board sit on their carrier's deck and move with it (their wheels turn in the air)."""
        c = self.cid
        decks: dict[int, tuple] = {}  # a carrier's pose and velocity, read once (a carrier that rides is read anew)
        for i, (carrier, _slot) in self.carried.items():
            deck = decks.get(carrier)
            if deck is None:
                b = self.bodies[carrier]
                deck = (*pb.getBasePositionAndOrientation(b, physicsClientId=c),
                        *pb.getBaseVelocity(b, physicsClientId=c))
                if carrier not in self.carried:
                    decks[carrier] = deck
            (x, y, z), orn, v, w = deck
            top = z + self.profiles[carrier].height_m / 2 + self.profiles[i].height_m / 2 + 1e-3
            pb.resetBasePositionAndOrientation(self.bodies[i], [x, y, top], orn, physicsClientId=c)
            pb.resetBaseVelocity(self.bodies[i], v, w, physicsClientId=c)

    def _read_poses(self) -> None:
        c = self.cid
        get = pb.getBasePositionAndOrientation
        xs, ys, yaws = [], [], []
        for body in self.bodies:
            (x, y, _), (qx, qy, qz, qw) = get(body, physicsClientId=c)
            xs.append(x)
            ys.append(y)
            yaws.append(math.atan2(2 * (qw * qz + qx * qy), 1 - 2 * (qy * qy + qz * qz)))
        new = np.column_stack((xs, ys)) if self.bodies else self.pos
        moved = np.hypot(*(new - self.pos).T)
        if self.carried:  # a ride is not the robot's own travel
            moved[list(self.carried)] = 0.0
        self.odometer += moved
        self.pos = new
        self.yaw = np.array(yaws)

    # -- radio geometry (the Geometry the radio and UWB media ask) ---------------------------------------
    STATIC_RAY_MASK = 2  # Bullet puts static bodies (walls, obstacles) in its StaticFilter group: robots are skipped
    MAX_WALLS = 32

    def positions(self) -> np.ndarray:
        return self.pos

    def alive_mask(self) -> np.ndarray:
        return self.alive

    def walls(self, src: int, dsts: np.ndarray) -> np.ndarray:
        """Obstacles crossed by the straight line between robot ``src``'s antenna and each of ``dsts``'.

        One ray batch per crossing level: pybullet's ``reportHitNumber`` returns the k-th static body a ray
        enters, so the count is the number of levels that still hit. Robots do not count as walls: the rays are cast
        in the walls scene (``walls_cid``), which holds the static bodies alone.
        """
        dsts = np.asarray(dsts, dtype=int)
        row = self._walls_rows.get(src)  # robots move only in step_quantum: a count holds for the quantum
        if row is None:
            row = self._walls_rows[src] = np.full(self.n, -1, dtype=int)  # -1: not cast yet
        todo = dsts[row[dsts] < 0]
        if len(todo):  # only the pairs asked for (a ranging exchange asks for one, a broadcast for all)
            todo = np.unique(todo)
            row[todo] = self._cast_walls(src, todo)
        return row[dsts]

    def _cast_walls(self, src: int, dsts: np.ndarray) -> np.ndarray:
        counts = np.zeros(len(dsts), dtype=int)
        if not len(dsts):
            return counts
        if not self._walls_synced:  # the obstacles on a path, where they are now
            for body, twin in self._walls_twins.items():
                pos, orn = pb.getBasePositionAndOrientation(body, physicsClientId=self.cid)
                pb.resetBasePositionAndOrientation(twin, pos, orn, physicsClientId=self.walls_cid)
            if self.steps_done and (self._walls_twins or not self._walls_boxed):
                # bounding boxes as the full scene's physics steps leave them (grown by the contact threshold), which a
                # ray grazing a corner depends on
                pb.performCollisionDetection(physicsClientId=self.walls_cid)
                self._walls_boxed = True
            self._walls_synced = True
        z0 = self.profiles[src].height_m * 0.9
        frm = [float(self.pos[src, 0]), float(self.pos[src, 1]), z0]
        to = [[float(self.pos[d, 0]), float(self.pos[d, 1]), self.profiles[d].height_m * 0.9] for d in dsts.tolist()]
        rays = list(range(len(dsts)))  # a ray with no k-th wall has no (k+1)-th: only those that hit go on
        for level in range(self.MAX_WALLS):
            hits = pb.rayTestBatch([frm] * len(rays), [to[i] for i in rays], numThreads=1, reportHitNumber=level,
                                   collisionFilterMask=self.STATIC_RAY_MASK, fractionEpsilon=1e-4,
                                   physicsClientId=self.walls_cid)
            rays = [i for i, h in zip(rays, hits, strict=True) if h[0] >= 0]
            if not rays:
                break
            counts[rays] += 1
        return counts

    # -- sensing ------------------------------------------------------------------------------------
    def sensors(self, robot: int) -> dict[str, Any]:
        """What robot ``robot``'s board reads now: each of its parts' readings by name, and its battery voltage."""
        out: dict[str, Any] = {}
        for m in self._robot_models[robot]:
            out.update(m.sense(robot))
        out["battery_v"] = float(self.battery_v[robot])
        return out

    def close(self) -> None:
        for m in self.models.values():
            m.close()
        for c in (self.cid, self.walls_cid):
            if pb.isConnected(c):
                pb.disconnect(c)


def _path(r: RobotPlan) -> np.ndarray:
    """A stated motion as rows (t_s, x, y, yaw rad): a fixed body is a one-row path at its placement."""
    way = r.motion["waypoints"] if r.motion["kind"] == "scripted" else []
    if not way:
        return np.array([[0.0, r.pose[0], r.pose[1], r.pose[2]]])
    return np.array([[t, x, y, math.radians(yd)] for t, x, y, yd in way], dtype=float)


def path_pose(path: np.ndarray, t_s: float) -> tuple[float, float, float]:
    """The pose on a path at ``t_s``: linear between waypoints (the heading the short way round), the first
    before it starts and the last after it ends."""
    t = path[:, 0]
    k = int(np.searchsorted(t, t_s, side="right"))
    if k == 0:
        return float(path[0, 1]), float(path[0, 2]), float(path[0, 3])
    if k == len(t):
        return float(path[-1, 1]), float(path[-1, 2]), float(path[-1, 3])
    a, b = path[k - 1], path[k]
    f = (t_s - a[0]) / (b[0] - a[0])
    return (float(a[1] + f * (b[1] - a[1])), float(a[2] + f * (b[2] - a[2])),
            wrap(float(a[3] + f * wrap(float(b[3] - a[3])))))
