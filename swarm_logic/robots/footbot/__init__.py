"""The foot-bot's published interfaces: its device protocols (``interfaces``), the CAN database its base board and
range-and-bearing board speak (``footbot.dbc``), and the driver that reaches both over python-can (``can_boards``)."""

from __future__ import annotations

from functools import cache
from importlib.resources import files

import cantools
from cantools.database.can import Database

FOOTBOT_DBC = files(__package__) / "footbot.dbc"


@cache
def footbot_db() -> Database:
    """The foot-bot's CAN database (loaded once per process)."""
    return cantools.database.load_string(FOOTBOT_DBC.read_text(), database_format="dbc")
