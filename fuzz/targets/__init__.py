"""The registry of fuzz targets: one module per device or boundary, each with a ``TARGETS`` list of
``fuzz.harness.Target``; ``MODULE_OF`` says which module holds which target, so a fuzzing process imports (and has
atheris instrument) only its own target's code.

A new bus or device gets its module here, its targets in ``MODULE_OF``, and its seeds in ``fuzz/corpus/<name>/``
(``python -m fuzz seed NAME``); ``tests/fuzz`` checks the map against the modules.
"""

from __future__ import annotations

import importlib

from fuzz.harness import Target

MODULE_OF: dict[str, str] = {
    "xbee_api1": "xbee", "xbee_api2": "xbee", "xbee_at": "xbee", "xbee_driver": "xbee", "xbee_gateway": "xbee",
    "slcan": "slcan",
    "uwb_tlv": "uwb", "uwb_driver": "uwb",
    "zebro_radio": "zebro", "zebro_radio_driver": "zebro", "bno055": "zebro", "bno055_driver": "zebro",
    "zebro_utility_driver": "zebro", "zebrobus_leg": "zebro",
    "usb_iss": "usb_iss", "usb_iss_driver": "usb_iss",
    "can_medium": "can", "eswarbot_llc": "can", "llc_client": "can", "footbot_base": "can", "footbot_rab": "can",
    "footbot_driver": "can",
    "sonpi_board": "sonpi", "sonpi_board_driver": "sonpi", "sonpi_packets": "sonpi", "sonpi_plan": "sonpi",
    "mavlink_gateway": "mavlink", "mavlink_face": "mavlink",
    "hub_reply": "hub", "mavlink_world": "hub",
}
MODULES = tuple(dict.fromkeys(MODULE_OF.values()))


def module_targets(module: str) -> list[Target]:
    """The targets of ``fuzz.targets.<module>`` (importing it)."""
    return list(importlib.import_module(f"fuzz.targets.{module}").TARGETS)


def get(name: str) -> Target:
    """Target ``name``, importing its module only. KeyError for an unknown one."""
    for t in module_targets(MODULE_OF[name]):
        if t.name == name:
            return t
    raise KeyError(f"fuzz.targets.{MODULE_OF[name]} has no target {name!r}")


def all_targets() -> dict[str, Target]:
    """Every target by name, in ``MODULE_OF``'s order (importing every module)."""
    found = {t.name: t for m in MODULES for t in module_targets(m)}
    return {name: found[name] for name in MODULE_OF if name in found}
