"""The ZigBee stack inside an XBee ZB module, below its host API: the APS addressing of a frame, the ZigBee Device
Object (ZDO) server every ZigBee node runs, and the Digi Drop-In-Networking (DIN) profile's device endpoint, over
which remote AT commands and node discovery travel (sans-IO, no time).

Sources:

- [ZB-SPEC] ZigBee Specification (053474r17), 2.4.3 "ZDP client services" and 2.4.4 "ZDP server services": each
  request's cluster (the response's is the request's | 0x8000), the transaction sequence number first in every
  ZDP frame, little-endian fields, NOT_SUPPORTED (0x84) for a request the device does not serve; 2.3.2.3 "Node
  descriptor" (13 bytes).
- [KB-DIN] Digi knowledge base, "Using Digi's Application's Cluster IDs and End points on a Digi XBee": the DIN
  profile 0xC105, the Digi Device Objects (DDO) endpoint 0xE6 (AT commands, local or remote), the data endpoint
  0xE8, serial data on cluster 0x0011, node identification 0x0095.
- [ZB] the XBee ZB manual (see ``xbee``): the ND response's fields (MY, SH, SL, NI, parent network address, device
  type, status, profile ID, manufacturer ID, DD when NO bit 0 is set), Digi's manufacturer code 0x101E; the ZDO
  requests it lists (NWK_addr, IEEE_addr, Node_Desc, Simple_Desc, Active_EP, Match_Desc, Mgmt_Lqi, Mgmt_Rtg, ...).
- [DIGI-C] Digi's XBee ANSI C library, ``include/wpan/aps.h``: the DIN clusters ND 0x0015, DN 0x0016, remote
  command request 0x0021 and response 0x00A1, node identification 0x0095, DN response 0x0096.
- The node descriptor's bytes are zigpy-xbee's, taken from a real XBee (router logical type, 2.4 GHz, MAC
  capabilities 0x8E, manufacturer 0x101E, buffer 82, transfer sizes 255), with the server mask 0 that a ZigBee-2007
  stack of the 2x7x firmware's age sends (zigpy's 0x2C00 declares a later stack revision).

Assumptions where no source says more: the payloads exchanged on the DDO endpoint (remote AT request and response,
node discovery request and response) are Digi's own and unpublished; they are encoded here as ``ddo_*`` below, a
transaction number first like every ZDP frame; nothing outside two emulated modules ever reads them.
"""

from __future__ import annotations

from dataclasses import dataclass

# APS addressing of a frame: (profile, cluster, source endpoint, destination endpoint)
ZDO_PROFILE, ZDO_EP = 0x0000, 0x00
DIN_PROFILE, DDO_EP, DATA_EP = 0xC105, 0xE6, 0xE8
SERIAL_DATA_CLUSTER = 0x0011
DATA_APS = (DIN_PROFILE, SERIAL_DATA_CLUSTER, DATA_EP, DATA_EP)  # what a 0x10 Transmit Request sends
DIGI_MANUFACTURER = 0x101E

# Digi's clusters for what the modules say to each other ([DIGI-C]); their payloads are our encoding
DDO_REMOTE_AT_REQ, DDO_REMOTE_AT_RSP = 0x0021, 0x00A1
DDO_ND_REQ, DDO_ND_RSP = 0x0015, 0x0095
DDO_DN_REQ, DDO_DN_RSP = 0x0016, 0x0096

# ZDP clusters served ([ZB-SPEC] 2.4.3)
NWK_ADDR_REQ, IEEE_ADDR_REQ, NODE_DESC_REQ, ACTIVE_EP_REQ = 0x0000, 0x0001, 0x0002, 0x0005
# what the XBee's application, not its stack, answers: with AO = 3 the host gets them instead ([ZB] AO)
APPLICATION_ZDO = frozenset((0x0004, ACTIVE_EP_REQ, 0x0006))
MGMT_LQI_REQ, MGMT_RTG_REQ = 0x0031, 0x0032
ZDP_SUCCESS, ZDP_INV_REQUESTTYPE, ZDP_DEVICE_NOT_FOUND, ZDP_NOT_SUPPORTED = 0x00, 0x80, 0x81, 0x84

# device types, as ND and the node descriptor give them
COORDINATOR, ROUTER, END_DEVICE = 0, 1, 2


def valid_aps(aps: object) -> bool:
    """An APS addressing as frames carry it: four ints, profile and cluster 16-bit, endpoints 8-bit."""
    return (isinstance(aps, list | tuple) and len(aps) == 4 and all(type(v) is int for v in aps)
            and 0 <= aps[0] <= 0xFFFF and 0 <= aps[1] <= 0xFFFF and 0 <= aps[2] <= 0xFF and 0 <= aps[3] <= 0xFF)


@dataclass(frozen=True)
class NodeInfo:
    """What a node's ZDO server and its ND answer say of it."""

    ieee: int
    nwk: int
    node_id: bytes
    device_type: int = ROUTER
    parent: int = 0xFFFE  # a router has no parent


def node_descriptor(device_type: int) -> bytes:
    """[ZB-SPEC] 2.3.2.3, 13 bytes little-endian: logical type; 2.4 GHz band; MAC capabilities of a mains-powered
    full-function device whose receiver is on when idle and which is given an address (an end device: battery, receiver
    off); Digi's manufacturer code; buffer 82; incoming transfer 255; server mask 0; outgoing transfer 255."""
    mac_caps = 0x8E if device_type != END_DEVICE else 0x80
    return bytes((device_type & 0x07, 0x40, mac_caps)) + DIGI_MANUFACTURER.to_bytes(2, "little") + bytes((0x52,)) \
        + (0xFF).to_bytes(2, "little") + (0).to_bytes(2, "little") + (0xFF).to_bytes(2, "little") + b"\x00"


def zdo_answer(cluster: int, payload: bytes, me: NodeInfo, neighbours: list[tuple[int, int, int]] | None = None
               ) -> tuple[int, bytes] | None:
    """A ZDP request to this node -> (response cluster, response payload), or None for no answer: a response
    cluster (>= 0x8000) or an empty request. ``neighbours``: (ieee, nwk, lqi) of the nodes heard, for Mgmt_Lqi."""
    if cluster >= 0x8000 or not payload:
        return None
    tsn, body = payload[0], payload[1:]
    rsp = cluster | 0x8000
    ieee = me.ieee.to_bytes(8, "little")
    nwk = me.nwk.to_bytes(2, "little")
    if cluster == NWK_ADDR_REQ:
        if len(body) < 10:
            return rsp, bytes((tsn, ZDP_INV_REQUESTTYPE))
        if int.from_bytes(body[:8], "little") != me.ieee:
            return None  # a broadcast request for another node: only that node answers
        return rsp, bytes((tsn, ZDP_SUCCESS)) + ieee + nwk
    if cluster == IEEE_ADDR_REQ:
        if len(body) < 4:
            return rsp, bytes((tsn, ZDP_INV_REQUESTTYPE))
        if int.from_bytes(body[:2], "little") != me.nwk:
            return None
        return rsp, bytes((tsn, ZDP_SUCCESS)) + ieee + nwk
    if cluster == NODE_DESC_REQ:
        if len(body) < 2 or int.from_bytes(body[:2], "little") != me.nwk:
            return rsp, bytes((tsn, ZDP_DEVICE_NOT_FOUND)) + body[:2].ljust(2, b"\x00")
        return rsp, bytes((tsn, ZDP_SUCCESS)) + nwk + node_descriptor(me.device_type)
    if cluster == ACTIVE_EP_REQ:
        if len(body) < 2 or int.from_bytes(body[:2], "little") != me.nwk:
            return rsp, bytes((tsn, ZDP_DEVICE_NOT_FOUND)) + body[:2].ljust(2, b"\x00") + b"\x00"
        return rsp, bytes((tsn, ZDP_SUCCESS)) + nwk + bytes((2, DDO_EP, DATA_EP))
    if cluster == MGMT_LQI_REQ:
        start = body[0] if body else 0
        table = neighbours or []
        rows = table[start:start + 2]  # two 22-byte entries fit an APS frame
        out = bytes((tsn, ZDP_SUCCESS, len(table), start, len(rows)))
        for n_ieee, n_nwk, lqi in rows:
            # extended PAN (unknown here: 0), IEEE, NWK, device type router | rx on idle | relationship sibling,
            # permit joining unknown, depth 0xFF (unknown), LQI
            out += (0).to_bytes(8, "little") + n_ieee.to_bytes(8, "little") + n_nwk.to_bytes(2, "little") \
                + bytes((ROUTER | 1 << 2 | 2 << 4, 0x02, 0xFF, lqi & 0xFF))
        return rsp, out
    return rsp, bytes((tsn, ZDP_NOT_SUPPORTED))


def nd_record(me: NodeInfo, dd: int | None = None, rssi_dbm: int | None = None) -> bytes:
    """The body of an ND (or DN) response ([ZB]): MY, SH SL, NI and its NUL, parent, device type, status (0),
    profile, manufacturer; then DD (NO bit 0) and the last hop's RSSI (-dBm) when asked for."""
    out = me.nwk.to_bytes(2, "big") + me.ieee.to_bytes(8, "big") + me.node_id + b"\x00" + me.parent.to_bytes(2, "big") \
        + bytes((me.device_type, 0)) + DIN_PROFILE.to_bytes(2, "big") + DIGI_MANUFACTURER.to_bytes(2, "big")
    if dd is not None:
        out += dd.to_bytes(4, "big")
    if rssi_dbm is not None:
        out += bytes((min(max(-rssi_dbm, 0), 0xFF),))
    return out


# -- the DDO endpoint's messages (our encoding: see the module docstring) -------------------------------------------
def ddo_remote_at_req(tsn: int, options: int, cmd: bytes, param: bytes) -> bytes:
    return bytes((tsn & 0xFF, options & 0xFF)) + bytes(cmd[:2]) + bytes(param)


def parse_remote_at_req(payload: bytes) -> tuple[int, int, bytes, bytes] | None:
    if len(payload) < 4:
        return None
    return payload[0], payload[1], payload[2:4], payload[4:]


def ddo_remote_at_rsp(tsn: int, cmd: bytes, status: int, value: bytes) -> bytes:
    return bytes((tsn & 0xFF,)) + bytes(cmd[:2]) + bytes((status & 0xFF,)) + bytes(value)


def parse_remote_at_rsp(payload: bytes) -> tuple[int, bytes, int, bytes] | None:
    if len(payload) < 4:
        return None
    return payload[0], payload[1:3], payload[3], payload[4:]


def ddo_nd_req(tsn: int, nt_100ms: int, node_id: bytes) -> bytes:
    """A node discovery's broadcast: who asks (its tsn), the window to answer in (NT, 100 ms), the NI sought."""
    return bytes((tsn & 0xFF, nt_100ms & 0xFF)) + bytes(node_id[:20])


def parse_nd_req(payload: bytes) -> tuple[int, int, bytes] | None:
    if len(payload) < 2:
        return None
    return payload[0], payload[1], payload[2:22]
