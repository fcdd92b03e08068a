"""``swarm-sitl list``: the robots, behaviours, robot devices, media, services, studies and experiments this
installation found, and where each comes from (an entry point's ``module:attr``, or ``registered`` in the process)."""

from __future__ import annotations

import argparse
import json
from typing import Any

from bridge.core.registry import MEDIA, ROBOTS, SERVICES, STUDIES
from swarm_logic.behaviours import BEHAVIOURS
from swarm_logic.devices import DEVICES
from swarm_logic.plugins import PluginError


def catalogue() -> dict[str, list[dict[str, Any]]]:
    """Every plugin found, by kind; one that cannot be loaded is listed with its error."""
    out: dict[str, list[dict[str, Any]]] = {}
    for kind, reg, describe in (
            ("robots", ROBOTS, lambda s: s.title),
            ("behaviours", BEHAVIOURS, _first_sentence),
            ("devices", DEVICES, _first_sentence),
            ("media", MEDIA, _first_sentence),
            ("services", SERVICES, lambda s: s.title),
            ("studies", STUDIES, lambda s: s.title)):
        rows = []
        for name in reg.names():
            try:
                obj = reg.get(name)
                rows.append({"name": name, "from": reg.origin(name), "about": describe(obj)})
            except Exception as e:  # a broken plugin is shown, not fatal
                rows.append({"name": name, "from": "?", "about": f"cannot load: {e}"})
        out[kind] = rows
    from bridge.experiments.runner import experiments

    try:
        out["experiments"] = [{"name": n, "from": f"{c.__module__}:{c.__qualname__}", "about": c.title}
                              for n, c in experiments().items()]
    except (PluginError, ImportError) as e:
        out["experiments"] = [{"name": "?", "from": "?", "about": f"cannot load: {e}"}]
    return out


def _first_sentence(obj: Any) -> str:
    doc = " ".join((obj.__doc__ or "").split())
    return doc.split(". ")[0].removesuffix(".")


def cmd_list(a: argparse.Namespace) -> int:
    cat = catalogue()
    if a.json:
        print(json.dumps(cat, indent=1))
        return 0
    for kind, rows in cat.items():
        if a.kind and kind != a.kind:
            continue
        print(f"{kind}:")
        width = max((len(r["name"]) for r in rows), default=0)
        for r in rows:
            print(f"  {r['name']:<{width}}  {r['about']}  [{r['from']}]")
    return 0


def add_parser(sub: Any) -> None:
    p = sub.add_parser("list", help="the robots, behaviours, media, services, studies and experiments found (built "
                                    "in, by entry point or registered), and where each comes from")
    p.add_argument("kind", nargs="?", choices=["robots", "behaviours", "devices", "media", "services", "studies",
                                                  "experiments"])
    p.add_argument("--json", action="store_true", help="as JSON")
    p.set_defaults(fn=cmd_list)
