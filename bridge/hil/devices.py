"""Probing the real devices a session config names, before the session starts.

A hardware-in-the-loop session must not start against a device that is missing, held by another program or
answering garbage: each probe opens its device the way the session will, asks it to identify itself, and
returns a ``DeviceReport`` whose ``detail`` names the device and says what is wrong (or what answered).

- XBee: ``serial_for_url(..., exclusive=True)`` (an exclusive lock, so a port another program holds with one
  reports busy), then the project's own driver (``swarm_logic.drivers.xbee.XBee``) runs ``identify``; when nothing
  sensible comes back, the driver's counters tell silence from garbage (wrong baud rate, other API mode).
- CAN: ``can.Bus(**kwargs)`` for any python-can interface, then it listens for traffic and names the ids
  with the robots' DBC.
- MAVLink: a pymavlink connection string; it waits for a HEARTBEAT (sending a GCS heartbeat once a second,
  as a ground station does, so endpoints that only talk to a known peer answer) and counts the packets that
  failed their CRC or were not MAVLink meanwhile.

Every probe closes what it opened, also when it fails, and never raises for a device problem. Each imports its
libraries when it runs: the launcher imports this module for every session, and its children inherit its memory.
"""

from __future__ import annotations

import errno
import os
import stat
import time
from dataclasses import dataclass, field
from typing import Any

import serial

LISTEN_S = 0.5  # how long a CAN probe keeps listening after the first frame, to see what is on the bus
GCS_HEARTBEAT_S = 1.0
NETWORK_SCHEMES = ("udpin:", "udpout:", "udpbcast:", "udp:", "tcp:", "tcpin:")
# the driver's counters of bytes and frames that were not a good answer
_GARBAGE_FRAMES = ("checksum_errors", "bad_length", "truncated", "stalled", "malformed")


@dataclass
class DeviceReport:
    """The outcome of one probe: ``detail`` is one line for a person, ``info`` what the device said."""

    kind: str  # "xbee", "can" or "mavlink"
    name: str  # the device as the config names it
    ok: bool
    detail: str
    info: dict[str, Any] = field(default_factory=dict)


def _os_error_detail(e: OSError | serial.SerialException) -> str:
    """What an open failure means, from its errno."""
    code = getattr(e, "errno", None)
    if code in (errno.ENOENT, errno.ENODEV, errno.ENXIO):
        return "no such device"
    if code in (errno.EACCES, errno.EPERM):
        return "permission denied (is the user in the group owning the device, e.g. dialout?)"
    if code in (errno.EBUSY, errno.EAGAIN, errno.EWOULDBLOCK):
        return "busy: another program has it open"
    return str(e)


def _open_serial(port: str, baudrate: int) -> serial.SerialBase | str:
    """The port opened exclusively (non-blocking reads), or why it cannot be."""
    if "://" not in port:  # a device path, not one of pyserial's URL handlers
        try:
            mode = os.stat(port).st_mode
        except OSError as e:
            return _os_error_detail(e)
        if not stat.S_ISCHR(mode):
            return "not a serial device (not a character device)"
    try:
        return serial.serial_for_url(port, baudrate=baudrate, timeout=0, exclusive=True)
    except serial.SerialException as e:
        if "exclusively lock" in str(e):  # pyserial's flock failed: someone else holds the lock
            return "busy: locked by another process"
        return _os_error_detail(e)
    except ValueError as e:  # an unsupported baud rate or URL
        return str(e)


def probe_xbee(port: str, baudrate: int = 9600, api_mode: int = 1, timeout_s: float = 2.0) -> DeviceReport:
    """Open ``port`` and ask the XBee on it to identify itself (SH, SL, MY, NI, HV, VR) in API mode ``api_mode``."""
    from swarm_logic.clock import WallClock
    from swarm_logic.drivers.xbee import XBee, XBeeError, XBeeTimeout

    if api_mode not in (1, 2):
        raise ValueError(f"api_mode must be 1 or 2, got {api_mode!r}")
    setup = {"baudrate": baudrate, "api_mode": api_mode}
    ser = _open_serial(port, baudrate)
    if isinstance(ser, str):
        return DeviceReport("xbee", port, False, f"{port}: {ser}", setup)
    try:
        xb = XBee(ser, WallClock(), api_mode=api_mode)
        try:
            m = xb.identify(timeout=timeout_s)
        except XBeeTimeout as e:
            c = xb.counters
            noise = c["rx_bytes"] - c["frame_bytes"]  # bytes that were no part of a good frame
            info = {**setup, "counters": {k: v for k, v in c.items() if v}}
            if noise > 0:
                bad = sum(c[k] for k in _GARBAGE_FRAMES)
                return DeviceReport("xbee", port, False, (
                    f"{port}: answers garbage: {bad} malformed frames, {noise} noise bytes - "
                    f"wrong baud rate (tried {baudrate}) or not in API mode AP={api_mode}?"), info)
            heard = f" ({c['frames']} frames, none answering AT{e.command})" if c["frames"] else ""
            return DeviceReport("xbee", port, False, (
                f"{port}: no answer within {timeout_s:g} s{heard} - is the module powered and connected, "
                f"at {baudrate} baud in API mode AP={api_mode}?"), info)
        except XBeeError as e:
            return DeviceReport("xbee", port, False, f"{port}: refuses AT{e.command}: status {e.status}", setup)
        except serial.SerialException as e:  # unplugged while probing
            return DeviceReport("xbee", port, False, f"{port}: {e}", setup)
    finally:
        ser.close()
    info = {**setup, "serial": f"{m.serial64:016X}", "addr16": m.addr16, "node_id": m.node_id,
            "hw_version": m.hw_version, "fw_version": m.fw_version, "series": m.series,
            "modem_status": [s.name for s in xb.modem_status]}
    series = "Series 1 (802.15.4)" if m.series == 1 else "Series 2 (ZigBee)"
    return DeviceReport("xbee", port, True, (
        f"{port}: XBee {series}, serial {m.serial64:016X}, firmware {m.fw_version:04X}, "
        f"hardware {m.hw_version:04X}, NI {m.node_id!r}"), info)


def _can_name(kwargs: dict[str, Any]) -> str:
    iface = kwargs.get("interface", kwargs.get("bustype", "default"))
    channel = kwargs.get("channel")
    return f"{iface}:{channel}" if channel is not None else str(iface)


def probe_can(kwargs: dict[str, Any], timeout_s: float = 2.0) -> DeviceReport:
    """Open ``can.Bus(**kwargs)`` and wait up to ``timeout_s`` for traffic; once a frame came, listen
    ``LISTEN_S`` more and report the frames, their ids and DBC names. The bus is always shut down."""
    import can  # here, not at the top: the launcher lists devices without loading every probe's library

    from swarm_logic.robots.eswarbot import eswarbot_llc_db

    name = _can_name(kwargs)
    setup = {k: v for k, v in kwargs.items() if isinstance(v, str | int | float | bool)}
    try:
        bus = can.Bus(**kwargs)
    except can.CanInterfaceNotImplementedError as e:
        known = ", ".join(sorted(can.interfaces.VALID_INTERFACES))
        return DeviceReport("can", name, False, f"{name}: interface not available here: {e} (python-can knows "
                                                f"{known})", setup)
    except can.CanInitializationError as e:
        return DeviceReport("can", name, False, f"{name}: cannot open: {e}", setup)
    except OSError as e:
        return DeviceReport("can", name, False, f"{name}: cannot open: {_os_error_detail(e)}", setup)
    except Exception as e:  # interfaces raise what their vendor libraries raise (ValueError, TypeError, NameError)
        return DeviceReport("can", name, False, f"{name}: cannot open: {type(e).__name__}: {e}", setup)
    frames = errors = 0
    ids: dict[int, str] = {}
    names = {m.frame_id: m.name for m in eswarbot_llc_db().messages}
    try:
        end = time.monotonic() + timeout_s
        while (left := end - time.monotonic()) > 0:
            msg = bus.recv(timeout=left)
            if msg is None:
                continue
            if msg.is_error_frame:
                errors += 1
                continue
            if not frames:
                end = min(end, time.monotonic() + LISTEN_S)
            frames += 1
            ids.setdefault(msg.arbitration_id, names.get(msg.arbitration_id, ""))
    except can.CanError as e:
        return DeviceReport("can", name, False, f"{name}: receive failed: {e}", setup)
    finally:
        bus.shutdown()
    info = {**setup, "frames": frames, "error_frames": errors, "ids": dict(sorted(ids.items()))}
    if not frames:
        why = f"only {errors} error frames" if errors else "no traffic"
        return DeviceReport("can", name, False, (
            f"{name}: {why} within {timeout_s:g} s - is the board powered and the bitrate right?"), info)
    seen = ", ".join(f"{n} (0x{i:03X})" if n else f"0x{i:03X}" for i, n in sorted(ids.items()))
    return DeviceReport("can", name, True, f"{name}: {frames} frames, {len(ids)} ids: {seen}", info)


def _mavutil() -> Any:
    """pymavlink's mavutil, imported when a MAVLink probe runs (it costs tens of MB in every process that imports
    it, and the launcher's children inherit its memory until they exec)."""
    os.environ.setdefault("MAVLINK20", "1")  # parse and send MAVLink 2 (it also accepts MAVLink 1 packets)
    from pymavlink import mavutil

    return mavutil


def _enum_name(enum: str, value: int) -> str:
    entry = _mavutil().mavlink.enums.get(enum, {}).get(value)
    return entry.name if entry is not None else str(value)


def probe_mavlink(url: str, timeout_s: float = 3.0, source_system: int = 255, baudrate: int = 115200) -> DeviceReport:
    """Connect to ``url`` (``udpin:HOST:PORT``, ``udpout:HOST:PORT``, ``tcp:HOST:PORT``, ... or a serial device
    at ``baudrate``) and wait up to ``timeout_s`` for a HEARTBEAT from another system or component."""
    mavutil = _mavutil()
    setup: dict[str, Any] = {"url": url}
    if not url.startswith(NETWORK_SCHEMES):
        ser = _open_serial(url, baudrate)  # pymavlink opens without a lock: check it is free first
        if isinstance(ser, str):
            return DeviceReport("mavlink", url, False, f"{url}: {ser}", setup)
        ser.close()
    try:
        conn = mavutil.mavlink_connection(url, baud=baudrate, source_system=source_system, dialect="common",
                                          retries=0, autoreconnect=False)
    except (OSError, serial.SerialException) as e:
        return DeviceReport("mavlink", url, False, f"{url}: cannot open: {_os_error_detail(e)}", setup)
    except ValueError as e:
        return DeviceReport("mavlink", url, False, f"{url}: bad connection string: {e}", setup)
    bad_crc = bad_data = 0
    hb = None
    try:
        end = time.monotonic() + timeout_s
        next_hb = 0.0
        while (now := time.monotonic()) < end:
            if now >= next_hb:
                conn.mav.heartbeat_send(mavutil.mavlink.MAV_TYPE_GCS, mavutil.mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
                next_hb = now + GCS_HEARTBEAT_S
            msg = conn.recv_msg()
            if msg is None:
                conn.select(min(0.05, end - now))
            elif msg.get_type() == "BAD_DATA":
                if "CRC" in str(msg.reason):
                    bad_crc += 1
                else:
                    bad_data += 1
            elif msg.get_type() == "HEARTBEAT" and (msg.get_srcSystem(), msg.get_srcComponent()) != (
                    source_system, conn.source_component):
                hb = msg
                break
    except OSError as e:
        return DeviceReport("mavlink", url, False, f"{url}: receive failed: {_os_error_detail(e)}", setup)
    finally:
        conn.close()
    info = {**setup, "bad_crc": bad_crc, "bad_data": bad_data}
    garbage = f" ({bad_crc} packets with a bad CRC, {bad_data} bad data)" if bad_crc or bad_data else ""
    if hb is None:
        return DeviceReport("mavlink", url, False, f"{url}: no heartbeat within {timeout_s:g} s{garbage}", info)
    mav_type, autopilot = _enum_name("MAV_TYPE", hb.type), _enum_name("MAV_AUTOPILOT", hb.autopilot)
    info |= {"sysid": hb.get_srcSystem(), "compid": hb.get_srcComponent(), "type": mav_type, "autopilot": autopilot,
             "mavlink": 2 if hb.get_msgbuf()[0] == 0xFD else 1}
    return DeviceReport("mavlink", url, True, (
        f"{url}: system {hb.get_srcSystem()} component {hb.get_srcComponent()}, {mav_type}, {autopilot}{garbage}"),
        info)


@dataclass
class SessionDevice:
    """Something a session config opens to the outside world: a port it creates for outside programs, or a real
    device it uses (``real``: it must answer before the session starts)."""

    field: str  # the config field, e.g. "robots[1].xbee.device (r005)"
    kind: str  # "xbee", "can", "mavlink", "pty" (a robot model's own port), "wifi", "logic"
    target: str  # a path, a device or an endpoint
    real: bool
    note: str
    probe: Any = None  # () -> DeviceReport, for a real device

    def check(self) -> DeviceReport | None:
        return self.probe() if self.probe is not None else None


def session_devices(cfg: Any, out_dir: str = "runs/<config name>") -> list[SessionDevice]:
    """What a session of ``cfg`` (a ``bridge.core.config.Config``) would open, in robot order, then the MAVLink
    endpoint. Pseudo-terminal links are relative to the session's output directory ``out_dir``."""
    from bridge.core.endpoints import parse_endpoint

    found: list[SessionDevice] = []
    r = 0
    for i, g in enumerate(cfg.robots):
        for rid in range(r, r + g.count):
            who = f"r{rid:03d}"
            x = g.xbee
            if x is not None and x.pty:
                found.append(SessionDevice(f"robots[{i}].xbee.pty ({who})", "xbee",
                                           f"{out_dir}/{x.pty.replace('{id}', str(rid))}", False,
                                           f"simulated XBee Series {x.series}, API {x.api_mode}, {x.baud} baud: "
                                           "a pseudo-terminal for XCTU, digi-xbee or a robot's logic"))
            if x is not None and x.device:
                found.append(SessionDevice(
                    f"robots[{i}].xbee.device ({who})", "xbee", x.device, True,
                    f"real XBee, expected Series {x.series}, API {x.api_mode}, {x.baud} baud",
                    lambda x=x: probe_xbee(x.device, x.baud, x.api_mode)))
            for opt, link in g.model_ptys().items():  # the robot model's own modules (a Zebro's bus, radio, ...)
                found.append(SessionDevice(f"robots[{i}].{opt} ({who})", "pty",
                                           f"{out_dir}/{link.replace('{id}', str(rid))}", False,
                                           f"the robot's {opt.removesuffix('_pty')} on a pseudo-terminal, for a "
                                           "program outside the session"))
            if g.can.slcan_pty:
                found.append(SessionDevice(f"robots[{i}].can.slcan_pty ({who})", "can",
                                           f"{out_dir}/{g.can.slcan_pty.replace('{id}', str(rid))}", False,
                                           f"the robot's CAN bus ({cfg.can.bitrate} bit/s) as an slcan adapter: "
                                           "python-can interface 'slcan'"))
            if g.can.device is not None:
                dev = g.can.device
                found.append(SessionDevice(
                    f"robots[{i}].can.device ({who})", "can", _can_name(dev), True,
                    "the robot's real LLC board: the session bridges its CAN bus there (expects the board's "
                    "traffic)", lambda dev=dev: probe_can({**dev, "ignore_config": True})))
            if g.vehicle is not None:
                v = g.vehicle
                found.append(SessionDevice(
                    f"robots[{i}].vehicle ({who})", "mavlink", v.url, True,
                    f"a MAVLink vehicle (system {v.target_system}) the robot's {g.behaviour} logic drives",
                    lambda v=v: probe_mavlink(v.url, baudrate=v.baudrate)))
            if g.wifi_udp is not None:
                found.append(SessionDevice(f"robots[{i}].wifi_udp ({who})", "wifi", g.wifi_udp, False,
                                           "UDP: the robot's node on the session's Wi-Fi network (port 0: any free "
                                           "one, printed when the session starts)"))
            if g.logic == "external":
                found.append(SessionDevice(f"robots[{i}].logic ({who})", "logic", "(outside the session)", False,
                                           f"the robot's {g.behaviour} logic runs outside, in wall time, through "
                                           "the ports above"))
            if g.logic == "remote":
                found.append(SessionDevice(f"robots[{i}].logic ({who})", "logic", f"{cfg.session.listen}", False,
                                           f"the robot's {g.behaviour} logic joins from another computer "
                                           "(swarm-sitl join), in simulated time"))
        r += g.count
    for i, gw in enumerate(cfg.xbee_gateways):
        found.append(SessionDevice(
            f"xbee_gateways[{i}] (r{r + i:03d})", "xbee", gw.device, True,
            f"real XBee joined to the simulated channel at ({gw.pose[0]:g}, {gw.pose[1]:g}), expected Series "
            f"{gw.series}, API {gw.api_mode}, {gw.baud} baud",
            lambda gw=gw: probe_xbee(gw.device, gw.baud, gw.api_mode)))
    m = cfg.mavlink
    if m.endpoint is not None:
        ep = parse_endpoint(m.endpoint)
        what = "listens there" if ep.mode == "udpin" else "sends to a ground station listening there"
        found.append(SessionDevice("mavlink.endpoint", "mavlink", m.endpoint + (" + robot id" if m.per_robot else ""),
                                   False, f"UDP: the swarm's MAVLink endpoint {what}; systems "
                                          f"{m.system_id_base}..{m.system_id_base + cfg.robot_count - 1}"))
    return found


def preflight(cfg: Any, config_path: str) -> None:
    """The launcher's check before a session starts (entry point ``swarm_sitl.preflight``): every real device the
    config names must answer, else a config error naming its field."""
    from bridge.core.config import ConfigError

    for d in session_devices(cfg):
        if d.real and not (rep := d.check()).ok:
            raise ConfigError(f"{config_path}: {d.field}: {rep.detail}")
