"""Hosts the firmware of one or more robots: per robot its LLC board (as its robot plugin builds it:
``RobotSpec.make_board``), the radio modules it carries (an XBee, a UWB module) and its robot model's own firmware
entities (``RobotSpec.modules``: a hexapod's leg modules), each an entity with its own schedule.

Per tick the host hands a due board the world's physical values and the CAN frames the bus delivered, and returns
what the board answers (the frames it transmitted, its pin outputs when they changed, its next loop time). A module
gets the bytes its UART received and the
radio events the medium delivered, and returns the bytes it sent to its host, what it puts on the air, and
when it next needs to run.
"""

from __future__ import annotations

import contextlib
import os
import pty
import tty
from collections import defaultdict
from pathlib import Path
from typing import TYPE_CHECKING, Any

from bridge.core.config import Config
from bridge.core.entities import entity, robot_of, uwb_addr16, xbee_serial64
from bridge.core.plan import Plan
from bridge.core.registry import robot_spec
from bridge.core.rng import stream
from firmware_sim.modules.slcan import SlcanAdapter
from firmware_sim.modules.uwb import UwbModule
from firmware_sim.modules.xbee import XBeeModule

if TYPE_CHECKING:
    from bridge.hil.xbee_gateway import XBeeGateway


class PtyLink:
    """A module's UART on a pseudo-terminal, so outside tools (XCTU, digi-xbee, minicom, python-can's slcan) can
    open it.

    The slave side is linked at ``link`` and kept open here, so a tool may close and reopen it. Bytes cross
    in raw mode, as on a USB-serial adapter; what the outside sends is read once per quantum.
    """

    def __init__(self, link: str, what: str = "xbee.pty") -> None:
        self.master, self.slave = pty.openpty()
        tty.setraw(self.slave)
        os.set_blocking(self.master, False)
        self.link = Path(link)
        self.link.parent.mkdir(parents=True, exist_ok=True)
        if self.link.is_symlink():
            self.link.unlink()  # a stale link of an earlier session
        elif self.link.exists():
            raise FileExistsError(f"{what}: {link} exists and is not a link; it is left alone")
        self.link.symlink_to(os.ttyname(self.slave))
        self.dropped = 0

    def read(self) -> bytes:
        chunks = []
        while True:
            try:
                data = os.read(self.master, 4096)
            except (BlockingIOError, OSError):
                break
            if not data:
                break
            chunks.append(data)
        return b"".join(chunks)

    def write(self, data: bytes) -> None:
        """What does not fit (nobody reads and the terminal's buffer is full) is lost and counted, as on a
        serial line without flow control."""
        try:
            n = os.write(self.master, data)
        except OSError:
            n = 0
        self.dropped += len(data) - n

    def close(self) -> None:
        if self.link.is_symlink():
            self.link.unlink()
        for fd in (self.master, self.slave):
            with contextlib.suppress(OSError):
                os.close(fd)


class CanBridge:
    """A robot's simulated CAN bus bridged to its real LLC board on a python-can interface (socketcan, slcan, any):
    frames other nodes put on the simulated bus go to the real one, frames from the real bus (the board's) go on
    the simulated one, once per quantum. A send the real adapter refuses is counted; an interface that fails to
    receive has failed or disappeared, and the robot fails with it."""

    def __init__(self, device: dict[str, Any]) -> None:
        import can

        self.can = can
        self.name = f"{device.get('interface')}:{device.get('channel')}"
        try:  # the host's python-can config must not change the device the session was given
            self.bus = can.Bus(**{**device, "ignore_config": True})
        except Exception as e:  # python-can raises many kinds for a missing or busy adapter
            raise RuntimeError(f"can.device {self.name}: cannot open the real board's bus: {e}") from None
        self.counters = {"to_board": 0, "from_board": 0, "send_failed": 0, "error_frames": 0, "remote_frames": 0}

    def exchange(self, frames: list[tuple[int, bytes, bool]]) -> list[tuple[int, bytes, bool]]:
        """Send ``frames`` (id, data, extended) to the real bus; return what arrived from it since the last call."""
        for arb_id, data, ext in frames:
            try:
                self.bus.send(self.can.Message(arbitration_id=arb_id, data=data, is_extended_id=ext), timeout=0)
                self.counters["to_board"] += 1
            except self.can.CanError:  # a full queue, the adapter bus-off: the frame is lost, as on the wire
                self.counters["send_failed"] += 1
        out = []
        while True:
            try:
                m = self.bus.recv(0)
            except Exception as e:
                raise RuntimeError(f"can.device {self.name}: the real board's bus failed or disappeared: {e}") from e
            if m is None:
                return out
            if m.is_error_frame:
                self.counters["error_frames"] += 1
            elif m.is_remote_frame:
                self.counters["remote_frames"] += 1
            else:
                self.counters["from_board"] += 1
                out.append((m.arbitration_id, bytes(m.data), m.is_extended_id))

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self.bus.shutdown()


class BoardFaults:
    """A board's reboots and drifting clock, as the world announced them (``bridge.core.faults``)."""

    def __init__(self) -> None:
        self.resets: list[tuple[int, int]] = []  # (reset at, setup() at), to come
        self.up_ns = 0  # the end of the current reset
        self.pins_off = False
        self.drifts: list[tuple[int, int | None, float]] = []  # (from, until, ppm)
        self.counters: dict[str, int] = defaultdict(int)

    def add(self, item: dict[str, Any]) -> None:
        if item["kind"] == "reboot":
            self.resets.append((int(item["at"]), int(item["up"])))
            self.resets.sort()
        elif item["kind"] == "drift":
            self.drifts.append((int(item["at"]), None if item["until"] is None else int(item["until"]),
                                float(item["ppm"])))

    def reset_due(self, t: int) -> bool:
        """A reset starts by ``t`` (the board is to be built anew)."""
        due = False
        while self.resets and self.resets[0][0] <= t:
            _, up = self.resets.pop(0)
            self.up_ns = max(self.up_ns, up)
            self.pins_off = False
            self.counters["reboots"] += 1
            due = True
        return due

    def in_reset(self, t: int) -> bool:
        return t < self.up_ns

    def local_ns(self, t: int) -> int:
        """The board's own clock at world time ``t``: each drift adds ``ppm`` of the time it has run."""
        return t + round(sum(self._gain(t, a, b, ppm) for a, b, ppm in self.drifts))

    def world_ns(self, local: int) -> int:
        """The world time at which the board's clock reads ``local`` (the first, rounded up)."""
        t = local
        for _ in range(40):  # a contraction by the drift's share (at most 0.2) per step
            nxt = local - round(sum(self._gain(t, a, b, ppm) for a, b, ppm in self.drifts))
            if nxt == t:
                break
            t = nxt
        while self.local_ns(t) < local:
            t += 1
        while self.local_ns(t - 1) >= local:
            t -= 1
        return t

    @staticmethod
    def _gain(t: int, a: int, b: int | None, ppm: float) -> float:
        end = t if b is None else min(t, b)
        return max(0, end - a) * ppm * 1e-6


class FirmwareHost:
    def __init__(self, plan: Plan, robots: tuple[int, ...]) -> None:
        cfg = Config.from_plan(plan.config)
        seed = cfg.session.seed
        self.llcs: dict[int, Any] = {}  # each robot's LLC board, as its robot plugin builds it (RobotSpec.board)
        self.xbees: dict[int, XBeeModule] = {}
        self.xbee_baud: dict[int, int] = {}
        self.ptys: dict[int, PtyLink] = {}
        self.uwbs: dict[int, UwbModule] = {}
        self.slcans: dict[int, tuple[SlcanAdapter, PtyLink]] = {}
        self.bridges: dict[int, CanBridge] = {}  # robots whose LLC is a real board
        self.gateways: dict[int, XBeeGateway] = {}
        self.own: dict[int, dict[str, Any]] = {}  # each robot model's own firmware entities (RobotSpec.modules)
        self.crash_ns = {f.robot: round(f.at_s * 1e9) for f in cfg.faults if f.kind == "firmware_crash"}
        self.plan, self.cfg = plan, cfg
        self.board_faults: dict[str, BoardFaults] = {}  # boards that reboot or whose clock drifts
        uwb_team = [r.id for r in plan.robots if r.uwb]
        self.uwb_baud = cfg.uwb.uart_baud
        for r in robots:
            rp = plan.robots[r]
            spec = robot_spec(rp.profile)
            if rp.gateway is None and spec.roles is not None:
                self.own[r] = spec.make_modules(rp, cfg)
            if rp.llc_role == "llc":
                self.llcs[r] = spec.make_board(rp)
            elif rp.llc_role == "can_bridge":
                self.bridges[r] = CanBridge(rp.can_device)
            if rp.sim_xbee:
                x = rp.xbee
                self.xbees[r] = XBeeModule(
                    series=x["series"], serial64=xbee_serial64(r), node_id=rp.name, rng=stream(seed, "xbee", r),
                    api_mode=x["api_mode"], baud=x["baud"], pan_id=x["pan_id"], channel=x["channel"],
                    power_level=x["power_level"], routing=x.get("routing", "one_hop"))
                if x.get("pty"):
                    self.ptys[r] = PtyLink(x["pty"])
                if rp.gateway is not None:  # its relay's driver (digi-xbee) only in a process that has one
                    from bridge.hil.xbee_gateway import XBeeGateway

                    self.gateways[r] = XBeeGateway(rp.gateway)
            if rp.slcan_pty:
                self.slcans[r] = (SlcanAdapter(cfg.can.bitrate, serial_number=f"{r % 10000:04d}"),
                                  PtyLink(rp.slcan_pty, "can.slcan_pty"))
            if rp.uwb:
                self.uwbs[r] = UwbModule(
                    addr16=uwb_addr16(r), robot=r, peers=[(p, uwb_addr16(p)) for p in uwb_team if p != r],
                    slot=uwb_team.index(r), n_slots=len(uwb_team), rng=stream(seed, "uwb", r),
                    cfg=cfg.uwb)

    def run(self, ent: str, t_ns: int, inputs: dict[str, Any]) -> dict[str, Any]:
        r = robot_of(ent)
        if "crash_ns" in inputs:  # a crash injected while the session runs (Hub.inject_fault)
            self.crash_ns[r] = min(self.crash_ns.get(r, inputs["crash_ns"]), int(inputs["crash_ns"]))
        if t_ns >= self.crash_ns.get(r, t_ns + 1):
            raise RuntimeError(f"injected fault: robot {r}'s firmware crashed at {self.crash_ns[r] / 1e9:g} s")
        role = ent[ent.index("/") + 1:]
        if "faults" in inputs or ent in self.board_faults:
            return self._faulty(ent, r, role, t_ns, inputs)
        return self._run(r, role, t_ns, inputs)

    def _run(self, r: int, role: str, t_ns: int, inputs: dict[str, Any]) -> dict[str, Any]:
        own = self.own.get(r)
        if own is not None and role in own:
            return own[role].run(t_ns, inputs)
        if role == "llc":
            return self._llc(r, t_ns, inputs)
        if role == "xbee":
            return self._xbee(r, t_ns, inputs)
        if role == "slcan":
            return self._slcan(r, t_ns, inputs)
        if role == "can_bridge":
            return self._can_bridge(r, t_ns, inputs)
        return self._uwb(r, t_ns, inputs)

    def _faulty(self, ent: str, r: int, role: str, t_ns: int, inputs: dict[str, Any]) -> dict[str, Any]:
        """A run of a board with a fault (``bridge.core.faults``): a reboot holds it in reset, then builds it anew (RAM
        lost: ``setup()`` runs again); a drifting clock gives it its own time, and its wake-ups back in the world's."""
        bf = self.board_faults.setdefault(ent, BoardFaults())
        for item in inputs.get("faults", ()):
            bf.add(item)
        if bf.reset_due(t_ns):
            self._rebuild(r, role)
        if bf.in_reset(t_ns):
            bf.counters["inputs_lost_in_reset"] += len(inputs.get("in", ()))
            out: dict[str, Any] = {"out": [], "wake": bf.up_ns, "wom": False}
            off = getattr(self._board(r, role), "off_pins", None)
            if off is not None and not bf.pins_off:
                bf.pins_off = True
                out["pins"] = off()
            return out
        res = self._run(r, role, bf.local_ns(t_ns), inputs)
        if res.get("wake") is not None:
            res["wake"] = max(t_ns + 1, bf.world_ns(int(res["wake"])))
        return res

    def _board(self, r: int, role: str) -> Any:
        return self.llcs[r] if role == "llc" else self.own[r][role]

    def _rebuild(self, r: int, role: str) -> None:
        """Robot ``r``'s board ``role`` powered up anew, as its robot plugin builds it."""
        rp = self.plan.robots[r]
        spec = robot_spec(rp.profile)
        old = self._board(r, role)
        if role == "llc":
            self.llcs[r] = spec.make_board(rp)
        else:
            self.own[r][role] = spec.make_modules(rp, self.cfg)[role]
        close = getattr(old, "close", None)
        if close is not None:
            close()

    def _llc(self, r: int, t_ns: int, inputs: dict[str, Any]) -> dict[str, Any]:
        return self.llcs[r].run(t_ns, inputs)

    def _xbee(self, r: int, t_ns: int, inputs: dict[str, Any]) -> dict[str, Any]:
        m = self.xbees[r]
        link: PtyLink | XBeeGateway | None = self.ptys.get(r)
        if r in self.gateways:
            link = self.gateways[r]
            link.set_time(t_ns)
        uart = b"".join(item[1] for item in inputs["in"] if item[0] == "uart")
        if link is not None:
            uart += link.read()
        air = [item[1] for item in inputs["in"] if item[0] == "air"]
        res = m.step(t_ns, uart, air)
        out: list[list] = [["air", f] for f in res.air_tx]
        if res.uart_tx:
            if link is not None:
                link.write(res.uart_tx)
            else:
                out.append(["uart", "xbee", res.uart_tx, m.baud])
        if res.node is not None:
            out.append(["node", res.node])
        if m.baud != self.xbee_baud.get(r):  # BD changed: the line from the host is now sampled at the new rate
            self.xbee_baud[r] = m.baud
            out.append(["baud", "xbee", m.baud])
        if res.rssi_pwm is not None:
            out.append(["rssi_pwm", float(res.rssi_pwm)])
        wake = m.next_wake()
        if link is not None:  # poll the pseudo-terminal (the gateway's real module) every quantum
            wake = t_ns + 1 if wake is None else min(wake, t_ns + 1)
        return {"out": out, "wake": wake, "wom": True}

    def _slcan(self, r: int, t_ns: int, inputs: dict[str, Any]) -> dict[str, Any]:
        """The USB-CAN adapter on the robot's bus: frames from the bus to its serial line, the host's commands
        and frames from the line to the bus. Its pseudo-terminal is polled every quantum."""
        adapter, link = self.slcans[r]
        for item in inputs["in"]:
            if item[0] == "can0_state":
                adapter.set_bus_state(item[1], item[2], item[3])
            elif len(item) == 5:  # a frame from another node, at the time its last bit left the wire
                _bus, arb_id, data, ext, wire_end = item
                adapter.on_bus_frame(wire_end, arb_id, data, ext)
        adapter.feed(link.read())
        if out := adapter.take_output():
            link.write(out)
        frames = [["can0", f.arbitration_id, f.data, f.extended] for f in adapter.take_tx()]
        return {"out": frames, "wake": t_ns + 1, "wom": True}

    def _can_bridge(self, r: int, t_ns: int, inputs: dict[str, Any]) -> dict[str, Any]:
        """The robot's real LLC board, reached through a CAN interface: polled every quantum."""
        frames = [(item[1], item[2], item[3]) for item in inputs["in"] if item[0] == "can0" and len(item) == 5]
        back = self.bridges[r].exchange(frames)
        return {"out": [["can0", arb, data, ext] for arb, data, ext in back], "wake": t_ns + 1, "wom": True}

    def _uwb(self, r: int, t_ns: int, inputs: dict[str, Any]) -> dict[str, Any]:
        m = self.uwbs[r]
        uart = b"".join(item[1] for item in inputs["in"] if item[0] == "uart")
        events = [item[1] for item in inputs["in"] if item[0] == "uwb"]
        res = m.step(t_ns, uart, events)
        out: list[list] = [["uwb", q] for q in res.requests]
        if res.uart_tx:
            out.append(["uart", "uwb", res.uart_tx, self.uwb_baud])
        # Range results wait in the inbox until the module runs anyway (its next turn, or its host asks): they
        # carry their own times, so the module sees the same thing, with fewer wake-ups of the process.
        return {"out": out, "wake": m.next_wake(), "wom": ["uart"]}

    def stats(self) -> dict[str, dict]:
        """Each module's counters (malformed frames, buffer drops, ...), reported when the session ends."""
        out: dict[str, dict] = {}
        for r, m in self.xbees.items():
            out[entity(r, "xbee")] = dict(m.counters)
            if r in self.ptys:
                out[entity(r, "xbee")]["pty_dropped_bytes"] = self.ptys[r].dropped
        for r, m in self.uwbs.items():
            out[entity(r, "uwb")] = dict(m.counters)
        for r, (adapter, link) in self.slcans.items():
            out[entity(r, "slcan")] = {**adapter.counters, "pty_dropped_bytes": link.dropped}
        for r, bridge in self.bridges.items():
            out[entity(r, "can_bridge")] = dict(bridge.counters)
        for r, gw in self.gateways.items():
            out.setdefault(entity(r, "xbee"), {})["gateway"] = gw.stats()
        for r, own in self.own.items():
            for role, m in own.items():
                if getattr(m, "counters", None) is not None:
                    out[entity(r, role)] = dict(m.counters)
        for e, bf in self.board_faults.items():
            out.setdefault(e, {}).update(bf.counters)
        return out

    def stop(self) -> None:
        for link in [*self.ptys.values(), *(link for _, link in self.slcans.values()), *self.bridges.values(),
                     *self.gateways.values()]:
            link.close()
        for own in self.own.values():
            for m in own.values():
                close = getattr(m, "close", None)
                if close is not None:
                    close()
