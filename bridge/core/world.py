"""The physical world: one pybullet DIRECT client with the arena, obstacles, light field and robots.

Each eSwarBot is one rigid cylinder (126 mm x 100 mm, 600 g). Its two DC motors are modelled in numpy for
all robots at once (first-order speed response to PWM and battery voltage, a dead band, per-wheel gain
and wheel-radius spread); the resulting differential-drive twist is imposed on the body every physics
step and pybullet resolves contacts with walls, obstacles and other robots. Encoders count the wheels'
rotation in 48-CPR pulses (a wheel that spins against a wall keeps counting, as a real one slips).
The sonar is one batched ray test for all robots, a cone of rays per sensor, at the sensor's rate.

Nothing here reads the wall clock or an unseeded random source; pybullet's banner goes to stdout, which
is never parsed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import pybullet as pb

from bridge.core.arena_map import occupancy
from bridge.core.config import ArenaCfg, BoxObstacle, Config
from bridge.core.plan import RobotPlan
from bridge.core.profile import RobotProfile
from bridge.core.registry import robot_profile
from bridge.core.rng import stream
from swarm_logic.geometry import wrap

# Li-ion open-circuit voltage per cell against state of charge (typical curve).
_OCV_SOC = np.array([0.0, 0.05, 0.1, 0.2, 0.4, 0.6, 0.8, 0.9, 1.0])
_OCV_V = np.array([3.0, 3.45, 3.6, 3.68, 3.76, 3.86, 4.0, 4.08, 4.2])
_V_NOMINAL_PER_CELL = 3.7


@dataclass
class Sensors:
    """Physical sensor values for one robot at one instant (what the board's pins are exposed to)."""

    encoders: tuple[int, int]
    sonar_m: float
    lux: float
    battery_v: float
    side_sonars_m: tuple[float, ...] = ()  # a robot with more sonars (TraxBot): the others, left then right


class World:
    def __init__(self, cfg: Config, robots: list[RobotPlan]) -> None:
        self.cfg = cfg
        self.seed = cfg.session.seed
        self.hz = cfg.world.physics_hz
        self.dt = 1.0 / self.hz
        self.steps_done = 0
        self.cid = pb.connect(pb.DIRECT)
        c = self.cid
        pb.setGravity(0, 0, -9.81, physicsClientId=c)
        pb.setTimeStep(self.dt, physicsClientId=c)
        pb.setPhysicsEngineParameter(numSolverIterations=cfg.world.solver_iterations, physicsClientId=c)
        plane = pb.createCollisionShape(pb.GEOM_PLANE, physicsClientId=c)
        pb.createMultiBody(0, plane, physicsClientId=c)
        self.static_rects: list[tuple[float, float, float, float, float]] = []  # cx, cy, sx, sy, yaw (plots)
        self.cylinders: list[tuple[float, float, float]] = []
        self._build_arena(cfg.arena)
        for ob in cfg.obstacles:
            if isinstance(ob, BoxObstacle):
                self._box(ob.x, ob.y, ob.size, math.radians(ob.yaw_deg))
            else:
                self._cylinder(ob.x, ob.y, ob.radius, ob.height)
        if cfg.arena.map:
            self._load_map(cfg.arena)
        self._build_robots(robots)
        # what the light sensors read instead of the light field, when a study installs one (an objective with
        # ``lux(x, y)``: the RDPSO study's mapping objective)
        self.lux_field: Any = None

    # -- scene ------------------------------------------------------------------------------------
    def _box(self, x: float, y: float, size: tuple[float, float, float], yaw: float = 0.0) -> None:
        half = [size[0] / 2, size[1] / 2, size[2] / 2]
        shape = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=half, physicsClientId=self.cid)
        orn = pb.getQuaternionFromEuler([0, 0, yaw])
        pb.createMultiBody(0, shape, basePosition=[x, y, half[2]], baseOrientation=orn, physicsClientId=self.cid)
        self.static_rects.append((x, y, size[0], size[1], yaw))

    def _cylinder(self, x: float, y: float, r: float, h: float) -> None:
        shape = pb.createCollisionShape(pb.GEOM_CYLINDER, radius=r, height=h, physicsClientId=self.cid)
        pb.createMultiBody(0, shape, basePosition=[x, y, h / 2], physicsClientId=self.cid)
        self.cylinders.append((x, y, r))

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
        self.profiles: list[RobotProfile] = [robot_profile(r.profile) for r in robots]
        self._spawn_bodies(robots)
        self._drivetrains(robots)
        self._sonar_rays()

    def _spawn_bodies(self, robots: list[RobotPlan]) -> None:
        """One rigid cylinder per robot (a gateway's antenna: a point nothing touches), the stated motions, and the
        robots that start on a carrier's conveyor."""
        n = self.n
        self.bodies: list[int] = []
        shapes: dict[str, int] = {}
        for r, prof in zip(robots, self.profiles, strict=True):
            if prof.name not in shapes:
                shapes[prof.name] = pb.createCollisionShape(
                    pb.GEOM_CYLINDER, radius=prof.radius_m, height=prof.height_m, physicsClientId=self.cid
                )
            x, y, yaw = r.pose
            if r.gateway is not None:  # a radio's antenna, not a body: nothing collides with it or sees it
                self.bodies.append(pb.createMultiBody(0, -1, basePosition=[x, y, prof.height_m / 2 + 1e-3],
                                                      physicsClientId=self.cid))
                continue
            body = pb.createMultiBody(
                prof.mass_kg, shapes[prof.name], basePosition=[x, y, prof.height_m / 2 + 1e-3],
                baseOrientation=pb.getQuaternionFromEuler([0, 0, yaw]), physicsClientId=self.cid,
            )
            izz = 0.5 * prof.mass_kg * prof.radius_m**2
            # The wheels are kinematic (the twist is imposed every step), so the body itself must not
            # rub on the floor; huge roll/pitch inertia keeps it upright when it hits something.
            pb.changeDynamics(body, -1, localInertiaDiagonal=[1e3, 1e3, izz], lateralFriction=0.0,
                              linearDamping=0.0, angularDamping=0.0, physicsClientId=self.cid)
            self.bodies.append(body)
        # bodies whose motion the config states (a real board's or vehicle's robot, a gateway): (t, x, y, yaw) rows
        self.paths = {r.id: _path(r) for r in robots if r.scripted}
        # robots riding on a carrier's conveyor: robot -> (carrier, slot); they drop off as its belt advances
        self.carried: dict[int, tuple[int, int]] = {r.id: (r.carrier, r.slot) for r in robots if r.carrier is not None}
        self.belt_m = np.zeros(n)  # each carrier's belt travel since power-up
        self.released: list[dict] = []  # releases since the hub last took them (t_ns, robot, carrier, pose)
        for i in self.carried:  # on board nothing touches them and they touch nothing
            pb.setCollisionFilterGroupMask(self.bodies[i], -1, 0, 0, physicsClientId=self.cid)

    def _drivetrains(self, robots: list[RobotPlan]) -> None:
        """Every robot's motors, wheels, battery and sensors as numpy arrays (one vectorised model for all), with
        each robot's own spread of wheel radius and motor gain from its seeded stream."""
        n, p = self.n, self.profiles
        self.wheel_r = np.empty((n, 2))
        self.gain = np.empty((n, 2))
        for i, prof in enumerate(p):
            g = stream(self.seed, "robot", i, "drivetrain")
            self.wheel_r[i] = prof.wheel_radius_m * (1 + prof.wheel_radius_spread * g.standard_normal(2))
            self.gain[i] = 1 + prof.motor_gain_spread * g.standard_normal(2)
        self.half_track = np.array([q.half_track_m for q in p])
        self.cpr = np.array([q.encoder_cpr for q in p], dtype=float)
        self.w_max = np.array([q.motor_max_wheel_rad_s for q in p])
        self.tau = np.array([q.motor_time_constant_s for q in p])
        self.deadband = np.array([q.motor_deadband_pwm for q in p], dtype=float)
        self.pwm = np.zeros((n, 2))
        self.omega = np.zeros((n, 2))
        self._w_ss = np.zeros((n, 2))
        self._decay = np.exp(-self.dt / self.tau)[:, None]
        self._tau_1ma = self.tau[:, None] * (1 - self._decay)
        self.angle = np.zeros((n, 2))
        self.alive = np.ones(n, dtype=bool)
        self.led = np.zeros((n, 3), dtype=np.uint8)
        self.soc = np.ones(n)
        self.cells = np.array([q.battery_cells for q in p], dtype=float)
        self.capacity_as = np.array([q.battery_capacity_mah * 3.6 for q in p])
        self.r_int = np.array([q.battery_internal_ohm for q in p])
        self.i_idle = np.array([q.current_idle_ma for q in p]) / 1000.0
        self.i_motor = np.array([q.current_motor_max_ma for q in p]) / 1000.0
        self.battery_v = self._battery_voltage(np.zeros(n))
        self.pos = np.array([[r.pose[0], r.pose[1]] for r in robots], dtype=float).reshape(n, 2)
        self.yaw = np.array([r.pose[2] for r in robots], dtype=float)
        self.odometer = np.zeros(n)
        self.sonar_m = np.array([q.sonar_max_range_m for q in p])  # each robot's front sonar
        self.sonars = [np.full(len(q.sonar_angles_deg), q.sonar_max_range_m) for q in p]  # all of its sonars
        self._sonar_rng = [stream(self.seed, "robot", i, "sonar") for i in range(n)]
        self._light_rng = [stream(self.seed, "robot", i, "light") for i in range(n)]
        self._light_noise = [q.light_noise_rel for q in p]
        self._sampled: tuple | None = None
        self._walls_rows: dict[int, np.ndarray] = {}

    def _sonar_rays(self) -> None:
        """The sonar ray batch: a cone of rays per sonar, every robot's sonars numbered consecutively."""
        n, p = self.n, self.profiles
        self._sonar_period_ns = round(1e9 / max(q.sonar_rate_hz for q in p)) if n else 0
        self._next_sonar_ns = 0
        # rays: a cone per sonar; ``_ray_sonar`` numbers every robot's sonars consecutively (robot i's first is
        # ``_sonar_base[i]``), ``_ray_owner`` is the robot
        cones = [np.linspace(-1, 1, q.sonar_rays) * math.radians(q.sonar_half_beam_deg) if q.sonar_rays > 1
                 else np.zeros(1) for q in p]
        offsets = [np.concatenate([c + math.radians(a) for a in q.sonar_angles_deg]) for c, q in zip(cones, p,
                                                                                                      strict=True)]
        counts = [len(q.sonar_angles_deg) for q in p]
        self._sonar_base = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(int) if n else np.zeros(0, int)
        self._ray_owner = np.concatenate([np.full(len(o), i) for i, o in enumerate(offsets)]) if n else np.zeros(0, int)
        self._ray_sonar = (np.concatenate([self._sonar_base[i] + np.repeat(np.arange(k), len(c))
                                           for i, (k, c) in enumerate(zip(counts, cones, strict=True))])
                           if n else np.zeros(0, int))
        self._sonar_count = int(sum(counts))
        self._ray_angle = np.concatenate(offsets) if n else np.zeros(0)
        self._ray_r0 = np.array([q.radius_m + 0.005 for q in p])
        self._ray_len = np.array([q.sonar_max_range_m for q in p])
        self._ray_z = np.array([q.height_m * 0.6 for q in p])

    # -- actuators --------------------------------------------------------------------------------
    def set_pwm(self, robot: int, left: int, right: int) -> None:
        if self.alive[robot]:
            self.pwm[robot] = (left, right)

    def set_belt(self, robot: int, steps: int) -> None:
        """The carrier's conveyor stepper has turned ``steps`` steps since power-up."""
        if self.alive[robot]:
            self.belt_m[robot] = steps * self.profiles[robot].conveyor_m_per_step

    def set_led(self, robot: int, rgb: tuple[int, int, int]) -> None:
        self.led[robot] = rgb

    def deplete(self, robot: int) -> None:
        """The robot's battery is exhausted (an injected fault): no charge left; ``kill`` stops the rest."""
        self.soc[robot] = 0.0
        self.battery_v[robot] = float(self._battery_voltage(np.zeros(self.n))[robot])

    def kill(self, robot: int) -> None:
        """A dead robot: motors off, it stays in the arena as an obstacle."""
        self.alive[robot] = False
        self.pwm[robot] = 0
        self.led[robot] = 0

    # -- stepping -----------------------------------------------------------------------------------
    def _battery_voltage(self, current: np.ndarray) -> np.ndarray:
        ocv = np.interp(self.soc, _OCV_SOC, _OCV_V) * self.cells
        return ocv - current * self.r_int

    def _motor_targets(self) -> None:
        """Steady-state wheel speeds for the current PWM and battery voltage (constant over a quantum)."""
        duty = np.abs(self.pwm)
        frac = np.clip((duty - self.deadband[:, None]) / (255.0 - self.deadband[:, None]), 0.0, 1.0)
        vscale = (self.battery_v / (_V_NOMINAL_PER_CELL * self.cells))[:, None]
        self._w_ss = np.sign(self.pwm) * frac * self.w_max[:, None] * self.gain * vscale

    def _motor_step(self) -> None:
        """Exact first-order response over one physics step; the wheel angle is its exact integral."""
        w_ss = self._w_ss
        dev = self.omega - w_ss
        self.angle += w_ss * self.dt + dev * self._tau_1ma
        self.omega = w_ss + dev * self._decay

    def step_quantum(self, t_ns: int, q_ns: int) -> None:
        """Advance physics from ``t_ns`` to ``t_ns + q_ns`` (whole 1/physics_hz steps, exact on average)."""
        target_steps = int((t_ns + q_ns) * self.hz // 1_000_000_000)
        c = self.cid
        self._motor_targets()
        reset = pb.resetBaseVelocity
        yaw = self.yaw.copy()
        stepped = False
        while self.steps_done < target_steps:
            self._motor_step()
            rim = self.omega * self.wheel_r
            v = 0.5 * (rim[:, 0] + rim[:, 1])
            w = (rim[:, 1] - rim[:, 0]) / (2 * self.half_track)
            # heading at mid-step (imposed turn rate); the true pose is read back once per quantum, so
            # a collision's effect on the heading is picked up within one quantum
            mid = yaw + 0.5 * w * self.dt
            vx = (v * np.cos(mid)).tolist()
            vy = (v * np.sin(mid)).tolist()
            wl = w.tolist()
            for i, body in enumerate(self.bodies):
                reset(body, (vx[i], vy[i], 0.0), (0.0, 0.0, wl[i]), physicsClientId=c)
            pb.stepSimulation(physicsClientId=c)
            yaw += w * self.dt
            self.steps_done += 1
            if self.paths:
                self._follow_paths(self.steps_done / self.hz)
            if self.carried:
                self._ride()
            stepped = True
        if stepped:
            self._read_poses()
        if self.carried:
            self._release(t_ns + q_ns)
        current = self.i_idle + self.i_motor * np.abs(self.pwm).sum(axis=1) / 510.0
        self.soc = np.clip(self.soc - current * (q_ns * 1e-9) / self.capacity_as, 0.0, 1.0)
        self.battery_v = self._battery_voltage(current)
        self._sampled = None
        self._walls_rows.clear()
        t_end = t_ns + q_ns
        if self.n and t_end >= self._next_sonar_ns:
            self._update_sonar()
            while self._next_sonar_ns <= t_end:
                self._next_sonar_ns += self._sonar_period_ns

    def _follow_paths(self, t_s: float) -> None:
        """Put every body with a stated motion where its path says at ``t_s``, moving as the path moves (so what
        hits it feels its motion); nothing pushes it off its path."""
        c = self.cid
        for i, path in self.paths.items():
            x, y, yaw = path_pose(path, t_s)
            x1, y1, yaw1 = path_pose(path, t_s + self.dt)
            z = self.profiles[i].height_m / 2 + 1e-3
            pb.resetBasePositionAndOrientation(self.bodies[i], [x, y, z], pb.getQuaternionFromEuler([0, 0, yaw]),
                                               physicsClientId=c)
            pb.resetBaseVelocity(self.bodies[i], [(x1 - x) * self.hz, (y1 - y) * self.hz, 0.0],
                                 [0.0, 0.0, wrap(yaw1 - yaw) * self.hz], physicsClientId=c)

    def _ride(self) -> None:
        """Robots on a conveyor sit on their carrier's deck and move with it (their wheels turn in the air)."""
        c = self.cid
        get = pb.getBasePositionAndOrientation
        for i, (carrier, _slot) in self.carried.items():
            (x, y, z), orn = get(self.bodies[carrier], physicsClientId=c)
            top = z + self.profiles[carrier].height_m / 2 + self.profiles[i].height_m / 2 + 1e-3
            pb.resetBasePositionAndOrientation(self.bodies[i], [x, y, top], orn, physicsClientId=c)
            v, w = pb.getBaseVelocity(self.bodies[carrier], physicsClientId=c)
            pb.resetBaseVelocity(self.bodies[i], v, w, physicsClientId=c)

    def _release(self, t_ns: int) -> None:
        """A robot whose slot the belt has passed drops off behind its carrier, on the floor, facing its way."""
        for i, (carrier, slot) in list(self.carried.items()):
            prof = self.profiles[carrier]
            if self.belt_m[carrier] + 1e-9 < slot * prof.conveyor_pitch_m:
                continue
            del self.carried[i]
            yaw = float(self.yaw[carrier])
            back = prof.radius_m + self.profiles[i].radius_m + 0.02
            x = float(self.pos[carrier, 0]) - back * math.cos(yaw)
            y = float(self.pos[carrier, 1]) - back * math.sin(yaw)
            c = self.cid
            pb.resetBasePositionAndOrientation(self.bodies[i], [x, y, self.profiles[i].height_m / 2 + 1e-3],
                                               pb.getQuaternionFromEuler([0, 0, yaw]), physicsClientId=c)
            pb.resetBaseVelocity(self.bodies[i], [0, 0, 0], [0, 0, 0], physicsClientId=c)
            pb.setCollisionFilterGroupMask(self.bodies[i], -1, 1, -1, physicsClientId=c)
            self.pos[i] = (x, y)
            self.yaw[i] = yaw
            self.released.append({"t_ns": t_ns, "robot": i, "carrier": carrier, "slot": slot,
                                  "pose": [round(x, 4), round(y, 4), round(yaw, 4)]})

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

    def _update_sonar(self) -> None:
        """One ray batch for every live robot's sonar cone; the nearest echo in the cone is the range."""
        live = np.flatnonzero(self.alive)
        if not len(live):
            return
        rays = self.alive[self._ray_owner]
        owner = self._ray_owner[rays]
        ang = self.yaw[owner] + self._ray_angle[rays]
        ca, sa = np.cos(ang), np.sin(ang)
        x, y = self.pos[owner, 0], self.pos[owner, 1]
        r0, r1, z = self._ray_r0[owner], self._ray_r0[owner] + self._ray_len[owner], self._ray_z[owner]
        froms = np.column_stack([x + r0 * ca, y + r0 * sa, z])
        tos = np.column_stack([x + r1 * ca, y + r1 * sa, z])
        hits = pb.rayTestBatch(froms.tolist(), tos.tolist(), numThreads=1, physicsClientId=self.cid)
        frac = np.array([h[2] if h[0] >= 0 else 1.0 for h in hits])
        nearest = np.ones(self._sonar_count)
        np.minimum.at(nearest, self._ray_sonar[rays], frac)
        for i in live.tolist():
            prof = self.profiles[i]
            rng = self._sonar_rng[i]
            moving = abs(self.omega[i]).max() * prof.wheel_radius_m > 0.01
            out = self.sonars[i]
            for k in range(len(out)):
                frac = float(nearest[self._sonar_base[i] + k])
                true_r = frac * prof.sonar_max_range_m + 0.005
                noise = rng.standard_normal()
                outlier = rng.random() < prof.sonar_outlier_p
                spurious = rng.uniform(prof.sonar_min_range_m, prof.sonar_max_range_m)
                if frac >= 1.0:
                    r = prof.sonar_max_range_m
                else:
                    r = true_r + noise * (prof.sonar_noise_m + prof.sonar_noise_rel * true_r)
                if moving and outlier:
                    r = spurious
                # inside its blind zone the ranger reports its minimum range (as MaxBotix sensors do)
                out[k] = float(min(max(r, prof.sonar_min_range_m), prof.sonar_max_range_m))
            self.sonar_m[i] = out[0]

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
        enters, so the count is the number of levels that still hit. Robots do not count as walls.
        """
        dsts = np.asarray(dsts, dtype=int)
        row = self._walls_rows.get(src)  # robots move only in step_quantum: a row holds for the quantum
        if row is None:
            row = self._walls_rows[src] = self._cast_walls(src, np.arange(self.n))
        return row[dsts]

    def _cast_walls(self, src: int, dsts: np.ndarray) -> np.ndarray:
        counts = np.zeros(len(dsts), dtype=int)
        if not len(dsts):
            return counts
        z0 = self.profiles[src].height_m * 0.9
        frm = [[float(self.pos[src, 0]), float(self.pos[src, 1]), z0]] * len(dsts)
        to = [[float(self.pos[d, 0]), float(self.pos[d, 1]), self.profiles[d].height_m * 0.9] for d in dsts.tolist()]
        for level in range(self.MAX_WALLS):
            hits = pb.rayTestBatch(frm, to, numThreads=1, reportHitNumber=level,
                                   collisionFilterMask=self.STATIC_RAY_MASK, fractionEpsilon=1e-4,
                                   physicsClientId=self.cid)
            hit = np.array([h[0] >= 0 for h in hits])
            if not hit.any():
                break
            counts += hit
        return counts

    # -- sensing ------------------------------------------------------------------------------------
    def _sample_all(self) -> None:
        """Noise-free encoder counts and illuminance of every robot, once per physics state."""
        counts = np.floor(self.angle * (self.cpr / (2 * math.pi))[:, None]).astype(np.int64)
        if self.lux_field is not None:
            lux = self.lux_field.lux(self.pos[:, 0], self.pos[:, 1])
        else:
            lux = self.cfg.light.illuminance(self.pos[:, 0], self.pos[:, 1])
        self._sampled = (counts.tolist(), lux.tolist(), self.sonar_m.tolist(), self.battery_v.tolist())

    def sensors(self, robot: int) -> Sensors:
        if self._sampled is None:  # invalidated by every step_quantum
            self._sample_all()
        counts, lux, sonar, batt = self._sampled
        noisy = lux[robot] * (1 + self._light_noise[robot] * self._light_rng[robot].standard_normal())
        sides = tuple(self.sonars[robot][1:].tolist()) if len(self.sonars[robot]) > 1 else ()
        return Sensors((counts[robot][0], counts[robot][1]), sonar[robot], max(noisy, 0.0), batt[robot], sides)

    def close(self) -> None:
        if pb.isConnected(self.cid):
            pb.disconnect(self.cid)


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
