"""The DeciZebro's body on six jointed C-legs, RHex-style, as pybullet bodies in contact with the floor (the
contact-level body model; ``legs.py`` is the cheaper gait-level one).

Each robot is one pybullet multibody: its box body (the profile's size) with six revolute hips, three a side (front,
middle, back), each turning a C-leg: a half circle of ``leg_radius_m`` from the hip (one end) to the toe (the other),
its convex side backward when the leg points down, as a chain of ``leg_segments`` capsules along the arc. Each hip is
driven by its leg module's DC gearmotor: the motor's torque ``stall_torque_nm * (duty * V / nominal_v - omega /
max_rad_s)`` (V the battery voltage), limited to the stall torque at that voltage, is applied as a joint torque every
physics step from the leg's speed after the previous one; the motor's rotor, seen through the gearbox, adds to the
leg's inertia about its hip. A dead robot's H-bridges are off: its legs go limp.

Nothing imposes the body's motion: walking emerges from the legs pushing on the floor through Coulomb friction (each
leg's own coefficient, the robot's seeded spread around ``leg_friction``), so legs slip when they push harder than
friction holds, a tripod gait walks, legs slower on one side turn it, a leg that stops is dragged. The legs meet
walls, obstacles and other robots' legs and bodies; the legs of one robot do not meet each other (they turn in
parallel planes on the real robot).

Legs are numbered 0-5: 0-2 left, front to back; 3-5 right, front to back; a leg's angle is 0 pointing down and grows
as it walks forward, as in the gait-level model.
"""

from __future__ import annotations

import itertools
import math
from typing import Any

import numpy as np
import pybullet as pb

from bridge.core.parts import Part
from bridge.core.rng import stream
from bridge.robots.decizebro.legs import LEGS, TWO_PI, LegMotors


class ContactLegsParams(Part):
    leg_radius_m: float  # the C's radius: hip to toe is twice that
    leg_thickness_m: float  # the capsules' radius
    leg_segments: int  # capsules along the half circle
    leg_mass_kg: float  # each leg; the body gets the rest of the profile's mass
    hip_x_m: float  # front and back hips ahead of / behind the body's centre (the middle one at it)
    hip_y_m: float  # the hips' (and legs') distance from the body's centre line
    hip_z_m: float  # the hips' height over the body's centre (negative: below it)
    max_rad_s: float  # no-load leg speed at full duty and nominal voltage
    nominal_v: float  # the motors' rated voltage
    stall_torque_nm: float  # at the leg, at nominal voltage
    stall_current_a: float  # at nominal voltage
    rotor_inertia_kgm2: float  # the motor's rotor seen at the leg, through the gearbox (inertia x ratio squared)
    leg_friction: float  # Coulomb friction coefficient of a leg on the floor
    body_friction: float  # of the body (its belly, its sides) on the floor and on other robots
    traction_spread: float  # relative 1-sigma spread of the legs' friction, per leg and robot
    com_z_m: float  # the body's centre of mass over its centre (negative: below it)
    min_physics_hz: float = 0.0  # the physics rate the contacts need at least (0: the session's)

    @property
    def physics_hz(self) -> float:
        return self.min_physics_hz

    def arc(self) -> list[tuple[float, float]]:
        """The leg's half circle as ``leg_segments + 1`` points (x forward, z up) in the hip's frame, the leg
        pointing down: the hip at (0, 0), the toe at (0, -2 r), the convex side backward (it comes down in front on its
        convex side, rolls over it and pushes off with its toe behind)."""
        r = self.leg_radius_m
        return [(-r * math.sin(a), -r + r * math.cos(a))
                for a in np.linspace(0.0, math.pi, self.leg_segments + 1).tolist()]

    def hips(self) -> list[tuple[float, float, float]]:
        """The six hips' positions in the body's frame, legs 0-5."""
        return [(x, side * self.hip_y_m, self.hip_z_m) for side in (1, -1) for x in (self.hip_x_m, 0.0, -self.hip_x_m)]

    def standing_z(self) -> float:
        """The body centre's height over the floor with every leg pointing down."""
        return 2 * self.leg_radius_m + self.leg_thickness_m - self.hip_z_m


class ContactLegs(LegMotors):
    name = "contact_legs"

    @classmethod
    def build_body(cls, world: Any, part: ContactLegsParams, profile: Any,
                   pose: tuple[float, float, float]) -> int | None:
        """The body and its six legs, standing on legs pointing down at ``pose``."""
        c = world.cid
        half = [profile.length_m / 2, profile.width_m / 2, profile.height_m / 2]
        box = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=half, physicsClientId=c)
        pts = part.arc()
        seg_pos, seg_orn, seg_len = [], [], []
        for (x0, z0), (x1, z1) in itertools.pairwise(pts):
            seg_pos.append([(x0 + x1) / 2, 0.0, (z0 + z1) / 2])
            seg_orn.append(pb.getQuaternionFromEuler([0.0, math.atan2(x1 - x0, z1 - z0), 0.0]))
            seg_len.append(math.hypot(x1 - x0, z1 - z0))
        n = len(seg_len)
        leg = pb.createCollisionShapeArray([pb.GEOM_CAPSULE] * n, radii=[part.leg_thickness_m] * n,
                                           lengths=seg_len, collisionFramePositions=seg_pos,
                                           collisionFrameOrientations=seg_orn, physicsClientId=c)
        x, y, yaw = pose
        body_mass = profile.mass_kg - LEGS * part.leg_mass_kg
        body = pb.createMultiBody(
            body_mass, box, basePosition=[x, y, part.standing_z() + 1e-3],
            baseInertialFramePosition=[0, 0, part.com_z_m], baseOrientation=pb.getQuaternionFromEuler([0, 0, yaw]),
            linkMasses=[part.leg_mass_kg] * LEGS, linkCollisionShapeIndices=[leg] * LEGS,
            linkVisualShapeIndices=[-1] * LEGS, linkPositions=[list(h) for h in part.hips()],
            linkOrientations=[[0, 0, 0, 1]] * LEGS, linkInertialFramePositions=[[0, 0, 0]] * LEGS,
            linkInertialFrameOrientations=[[0, 0, 0, 1]] * LEGS, linkParentIndices=[0] * LEGS,
            linkJointTypes=[pb.JOINT_REVOLUTE] * LEGS, linkJointAxis=[[0, 1, 0]] * LEGS, physicsClientId=c)
        lx, ly, lz = profile.length_m, profile.width_m, profile.height_m
        pb.changeDynamics(body, -1, localInertiaDiagonal=[body_mass * (ly**2 + lz**2) / 12,
                                                          body_mass * (lx**2 + lz**2) / 12,
                                                          body_mass * (lx**2 + ly**2) / 12],
                          lateralFriction=part.body_friction, linearDamping=0.0, angularDamping=0.0,
                          physicsClientId=c)
        # the leg's mass sits at its hip (its gravity torque is under 1 % of the stall torque); about the hip axis it
        # has its own inertia (a half circle's about one end: 2 m r^2) and the rotor's through the gearbox
        i_leg = part.leg_mass_kg * part.leg_radius_m**2
        i_axis = 2 * i_leg + part.rotor_inertia_kgm2
        for j in range(LEGS):
            pb.changeDynamics(body, j, localInertiaDiagonal=[i_leg, i_axis, i_leg],
                              jointDamping=0.0, linearDamping=0.0, angularDamping=0.0, physicsClientId=c)
        # no motor of pybullet's own: the leg's torque is the DC motor's, applied every step
        pb.setJointMotorControlArray(body, list(range(LEGS)), pb.VELOCITY_CONTROL, forces=[0.0] * LEGS,
                                     physicsClientId=c)
        return body

    def __init__(self, world: Any, robots: list[int], parts: list[ContactLegsParams]) -> None:
        super().__init__(world, robots, parts)
        n, p = len(robots), parts
        self.duty = np.zeros((n, LEGS))
        self.theta = np.zeros((n, LEGS))  # joint angle (rad, unwrapped)
        self.rate = np.zeros((n, LEGS))
        self.limp = np.zeros(n, dtype=bool)
        self.leg_r = np.array([q.leg_radius_m for q in p])
        self.w_max = np.array([q.max_rad_s for q in p])
        self.v_nom = np.array([q.nominal_v for q in p])
        self.t_stall = np.array([q.stall_torque_nm for q in p])
        self.a_per_nm = np.array([q.stall_current_a / q.stall_torque_nm for q in p])
        self._bodies = [world.bodies[r] for r in robots]
        self._joints = list(range(LEGS))
        c = world.cid
        plane_mu = pb.getDynamicsInfo(0, -1, physicsClientId=c)[1] or 1.0  # the floor, the world's first body
        self.traction = np.empty((n, LEGS))
        for k, r in enumerate(robots):
            g = stream(world.seed, "robot", r, "legs")
            self.traction[k] = np.clip(1 + p[k].traction_spread * g.standard_normal(LEGS), 0.5, 1.2)
            for j in range(LEGS):  # pybullet multiplies the two bodies' coefficients
                pb.changeDynamics(self._bodies[k], j, lateralFriction=p[k].leg_friction * self.traction[k, j]
                                  / plane_mu, physicsClientId=c)
        self._tau = np.zeros((n, LEGS))
        self._gain = np.zeros((n, LEGS))  # stall torque x duty x voltage ratio, per quantum
        self._limit = np.zeros((n, 1))
        self._amp_s = np.zeros(n)  # battery current x time over the quantum
        self._q_s = 0.0

    # -- what the leg modules' pins do and read ----------------------------------------------------------
    def kill(self, r: int) -> None:
        """The H-bridges are off: no torque, the legs go limp."""
        k = self.local[r]
        self.duty[k] = 0.0
        self.limp[k] = True

    # -- the quantum -------------------------------------------------------------------------------------
    def start_quantum(self, t_ns: int, q_ns: int) -> None:
        vscale = (self.world.battery_v[self.ids] / self.v_nom)[:, None]
        self._gain = self.t_stall[:, None] * self.duty * vscale
        self._limit = self.t_stall[:, None] * vscale
        self._amp_s[:] = 0.0
        self._q_s = q_ns * 1e-9

    def before_step(self) -> None:
        """Each motor's torque from its duty and the leg's speed (back EMF), within its stall torque."""
        tau = self._gain - self.t_stall[:, None] * self.rate / self.w_max[:, None]
        tau = np.clip(tau, -self._limit, self._limit)
        tau[self.limp] = 0.0
        self._tau = tau
        c, ctl, js, mode = self.world.cid, pb.setJointMotorControlArray, self._joints, pb.TORQUE_CONTROL
        for k, body in enumerate(self._bodies):
            ctl(body, js, mode, forces=tau[k].tolist(), physicsClientId=c)

    def after_step(self) -> None:
        dt = self.world.dt
        self._amp_s += (np.abs(self.duty * self._tau) * self.a_per_nm[:, None]).sum(axis=1) * dt
        get, c, js = pb.getJointStates, self.world.cid, self._joints
        for k, body in enumerate(self._bodies):
            states = get(body, js, physicsClientId=c)
            self.theta[k] = [s[0] for s in states]
            self.rate[k] = [s[1] for s in states]

    def load_a(self, load: np.ndarray) -> None:
        """What the motors draw from the battery: each its torque's current, times its duty (the H-bridge's share
        of the time), averaged over the quantum."""
        if self._q_s > 0:
            load[self.ids] += self._amp_s / self._q_s



ContactLegsParams.world_model = ContactLegs

# The DeciZebro's legs and motors (docs/zebro.md, "Two body models": figures, sources and assumptions).
_STALL_NM = 12.0 / (170 * TWO_PI / 60) * 3.8 * 0.65  # K = 12 V / 17.8 rad/s at the leg, x 3.8 A stall, x gears' 65 %
CONTACT_LEGS = ContactLegsParams(
    leg_radius_m=0.05,  # appendix B.4
    leg_thickness_m=0.008,  # assumed
    leg_segments=6,
    leg_mass_kg=0.05,  # assumed (a RHex C-leg, about three times the size, is 64 g)
    hip_x_m=0.09,
    hip_y_m=0.105 + 0.02,  # outside the body's sides (assumed)
    hip_z_m=-0.06,  # 20 mm over the body's bottom (assumed)
    com_z_m=-0.06,  # at the hips: the motors, gearboxes and battery sit low (assumed)
    max_rad_s=170 * TWO_PI / 60,  # 170 rpm at 12 V (appendix B.3)
    nominal_v=12.0,
    stall_torque_nm=_STALL_NM,
    stall_current_a=3.8,  # appendix B.3
    # a 37 mm gearmotor's rotor (about 1e-6 kg m^2) through a 35:1 gearbox (a 6000 rpm motor to 170 rpm; assumed)
    rotor_inertia_kgm2=1.2e-3,
    leg_friction=0.8,  # rubber on a hard floor (assumed)
    body_friction=0.3,  # plastic (assumed)
    traction_spread=0.03,  # as the gait-level model (assumed)
)
