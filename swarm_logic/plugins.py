"""Plugins by name: what a package offers under an entry-point group, or registers in code.

The same pattern as python-can's interfaces: a name maps to an object, found in the installed packages'
entry points (``[project.entry-points."swarm_sitl.behaviours"] rdpso = "pkg.module:Class"``) or registered with
``Registry.register`` (a test, a notebook, a package that is not installed). swarm-sitl's own behaviours, robots,
media and studies are found the same way as anyone else's, so the core names none of them.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Iterator
from importlib.metadata import entry_points
from typing import Any, Generic, TypeVar

T = TypeVar("T")


class PluginError(LookupError):
    """A plugin that is not there, or not what its group takes; the message names it and what there is."""


class Registry(Generic[T]):
    """The plugins of one entry-point ``group``; ``check`` refuses an object that is not of the group's kind."""

    def __init__(self, group: str, what: str, check: Callable[[Any], bool] | None = None) -> None:
        self.group = group
        self.what = what
        self._check = check
        self._found: dict[str, str] | None = None  # name -> "module:attr" from entry points
        self._loaded: dict[str, T] = {}
        self._origin: dict[str, str] = {}  # name -> where it came from (entry point value or "registered")

    def _entry_points(self) -> dict[str, str]:
        if self._found is None:
            self._found = {ep.name: ep.value for ep in entry_points(group=self.group)}
        return self._found

    def register(self, name: str, obj: T, *, replace: bool = False) -> T:
        """Make ``obj`` known as ``name`` in this process (without an installed package)."""
        if not name or not all(c.isalnum() or c in "_-." for c in name):
            raise PluginError(f"{self.what} name {name!r}: use letters, digits, '_', '-' and '.'")
        self._verify(name, obj)
        known = self._loaded.get(name)
        if known is not None and known is not obj and not replace:
            raise PluginError(f"{self.what} {name!r} is registered already ({self._origin.get(name)})")
        self._loaded[name] = obj
        self._origin[name] = "registered"
        return obj

    def unregister(self, name: str) -> None:
        self._loaded.pop(name, None)
        self._origin.pop(name, None)

    def names(self) -> list[str]:
        return sorted(set(self._entry_points()) | set(self._loaded))

    def origin(self, name: str) -> str:
        self.get(name)
        return self._origin[name]

    def get(self, name: str) -> T:
        """The plugin called ``name``; ``module:attr`` names any importable object of the right kind."""
        if name in self._loaded:
            return self._loaded[name]
        ref = self._entry_points().get(name)
        if ref is None and ":" in name:
            ref = name
        if ref is None:
            raise PluginError(f"unknown {self.what} {name!r}; known: {', '.join(self.names()) or 'none'}"
                              " (or module:attr)")
        obj = load_ref(ref)
        self._verify(name, obj)
        self._loaded[name] = obj
        self._origin[name] = ref
        return obj

    def items(self) -> Iterator[tuple[str, T]]:
        for name in self.names():
            yield name, self.get(name)

    def _verify(self, name: str, obj: Any) -> None:
        if self._check is not None and not self._check(obj):
            raise PluginError(f"{self.what} {name!r}: {obj!r} is not a {self.what}")


def load_ref(ref: str) -> Any:
    """The object a ``module:attr`` (or ``module:attr.sub``) reference names."""
    module, _, attr = ref.partition(":")
    if not module or not attr:
        raise PluginError(f"{ref!r} is not module:attr")
    try:
        obj: Any = importlib.import_module(module)
    except ModuleNotFoundError as e:
        raise PluginError(f"No module named {e.name!r} (for {ref})") from None
    for part in attr.split("."):
        try:
            obj = getattr(obj, part)
        except AttributeError:
            raise PluginError(f"{ref}: module {module!r} has no {attr!r}") from None
    return obj
