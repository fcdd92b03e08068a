"""Swarm behaviours by name: the ``swarm_sitl.behaviours`` entry points of every installed package (this one's in
``pyproject.toml``), those registered with ``register_behaviour``, or any ``module:Class`` controller."""

from __future__ import annotations

from swarm_logic.controller import Controller
from swarm_logic.plugins import PluginError, Registry

BEHAVIOURS: Registry[type[Controller]] = Registry(
    "swarm_sitl.behaviours", "behaviour", lambda c: isinstance(c, type) and issubclass(c, Controller))


def register_behaviour(name: str, cls: type[Controller]) -> type[Controller]:
    """Make a controller class known as behaviour ``name`` in this process (no installed package needed)."""
    return BEHAVIOURS.register(name, cls)


def load_behaviour(name: str) -> type[Controller]:
    """The controller class of behaviour ``name``; a ``ValueError`` names the behaviours there are."""
    try:
        return BEHAVIOURS.get(name)
    except PluginError as e:
        raise ValueError(str(e).replace("is not a behaviour", "is not a swarm_logic.controller.Controller subclass")
                         ) from None
