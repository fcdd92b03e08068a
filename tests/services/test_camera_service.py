"""The overhead camera service stepped directly (as its host runs it, without a session): the odometry it takes in is
fused, a malformed or misaddressed packet is counted and dropped, every frame's pose packet decodes, and the global
controller's mission and status handling."""

from __future__ import annotations

import math

import pytest

from bridge.core.config import Config
from bridge.core.plan import make_plan
from bridge.hosts.service import service_context
from swarm_logic.robots.sonpi import pose_packet as pp

Q = 10_000_000


def _service(mode: str, **options: object):
    cfg = Config.model_validate(
        {
            "arena": {"width_m": 4, "length_m": 4},
            "robots": [
                {"profile": "eswarbot", "count": 2, "placement": {"kind": "explicit", "poses": [[1, 1, 0], [3, 3, 0]]}}
            ],
            "services": [
                {"kind": "overhead_camera", "name": "cam", "options": {"mode": mode, **options}},
                {"kind": "global_controller", "name": "ctl", "options": {"target": [3.0, 3.0], "start_s": 0.5}},
            ],
        }
    )
    plan = make_plan(cfg)
    spec, ctx = service_context(plan, "cam")
    return spec.make(ctx), plan


def _truth(t_s: float) -> dict:
    """Robot 0 drives along x at 0.5 m/s from (1, 1); robot 1 stands."""
    return {"poses": {"x": [1.0 + 0.5 * t_s, 3.0], "y": [1.0, 3.0], "yaw": [0.0, 0.0], "alive": [True, True]}}


@pytest.mark.parametrize("mode", ["tracking", "noise"])
def test_odometry_is_fused_and_bad_packets_are_counted_and_dropped(mode: str) -> None:
    svc, _ = _service(mode, fps=10)
    try:
        sent = []
        for k in range(20):
            t_s = k * 0.1
            # robot 0's odometry: its own frame starts at 0, and it over-reads its speed by 10 %
            odo = pp.encode_odometry(k, t_s, pp.Odometry(0, 0.55 * t_s, 0.0, 0.0, 0.55, 0.0, 10 * k, 10 * k))
            datagrams = [("r000", odo)]
            if k == 5:
                datagrams += [
                    ("r000", b"\x00garbage"),
                    ("r001", odo),  # robot 1 claiming robot 0's odometry
                    ("ctl", pp.encode_mission(0, t_s, pp.Mission(True, 3.0, 3.0))),
                ]  # not for the camera
            res = svc.run(round(t_s * 1e9), {"in": [["wifi", list(d)] for d in datagrams], "sens": _truth(t_s)})
            assert res["wake"] == (k + 1) * 100_000_000 and res["wom"] is False
            sent += [item for item in res["out"] if item[0] == "wifi"]
        s = svc.summary()
        assert s["frames"] == 20 and s["odometry"] == 20 and s["malformed"] == 2 and s["ignored"] == 1
        assert s["fused"] >= 18 and s["frames_without_pose"] == 0
        assert s["position_error_m"]["p95"] < 0.02
        for _, dest, data in sent:
            assert dest is None  # broadcast to every node
            head, poses = pp.decode(data)
            assert head.type == pp.POSES and [p.id for p in poses] == [0, 1] and all(p.valid for p in poses)
        _, last = pp.decode(sent[-1][2])
        assert last[0].vx_mps == pytest.approx(0.55 * math.cos(last[0].yaw_rad), abs=1e-3)  # the odometry's speed
    finally:
        svc.close()


def _odometry_run(clock_s: float) -> tuple[list[bytes], dict]:
    """Robot 0 sends its odometry stamped on a clock ``clock_s`` ahead of the session's."""
    svc, _ = _service("noise", fps=10)
    try:
        sent = []
        for k in range(20):
            t_s = k * 0.1
            odo = pp.encode_odometry(k, t_s + clock_s, pp.Odometry(0, 0.55 * t_s, 0.0, 0.0, 0.55, 0.0, 10 * k, 10 * k))
            res = svc.run(round(t_s * 1e9), {"in": [["wifi", ["r000", odo]]], "sens": _truth(t_s)})
            sent += [item[2] for item in res["out"] if item[0] == "wifi"]
        return sent, svc.summary()
    finally:
        svc.close()


def test_odometry_on_a_robots_own_clock_is_fused_as_on_the_sessions() -> None:
    """A program outside the session (or a real Pi) stamps its odometry on its own clock: its first reading gives the
    offset, and the camera fuses its readings as if they were on the session's clock."""
    same, s0 = _odometry_run(0.0)
    own, s1 = _odometry_run(45_000.0)
    assert s0["clock_offsets_s"] == {} and s1["clock_offsets_s"] == {"0": -45_000.0}
    assert s0["fused_by_robot"] == s1["fused_by_robot"] and s1["fused_by_robot"]["0"] >= 18
    assert s1["fused_by_robot"]["1"] == 0  # robot 1 sent none
    for a, b in zip(same, own, strict=True):
        (_, pa), (_, pb) = pp.decode(a), pp.decode(b)
        assert [v for p in pa for v in (p.x_m, p.y_m, p.yaw_rad, p.vx_mps)] == pytest.approx(
            [v for p in pb for v in (p.x_m, p.y_m, p.yaw_rad, p.vx_mps)], abs=1e-5
        )


def test_the_global_controller_broadcasts_the_mission_and_collects_status() -> None:
    _, plan = _service("noise")
    spec, ctx = service_context(plan, "ctl")
    ctl = spec.make(ctx)
    missions = []
    for k in range(8):
        t_s = k * 0.25
        status = pp.encode_status(k, t_s, pp.Status(1, "running", True, 3.0 - 0.1 * k, 3.0, 0.0))
        datagrams = [("r001", status), ("r000", status), ("r000", b"junk")]
        res = ctl.run(round(t_s * 1e9), {"in": [["wifi", list(d)] for d in datagrams]})
        missions += [pp.decode(i[2])[1] for i in res["out"] if i[0] == "wifi"]
        assert res["wake"] == (k + 1) * 250_000_000
    assert [m.run for m in missions] == [False, False] + [True] * 6  # from start_s = 0.5
    s = ctl.summary()
    assert s["status"] == 8 and s["malformed"] == 16 and s["robots_reporting"] == 1
    assert s["arrived"] == {"1": 0.5}  # the first report within the goal radius while running
