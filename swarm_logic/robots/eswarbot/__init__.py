"""The robots' published interfaces (CAN database), as a companion computer ships them."""

from __future__ import annotations

from functools import cache
from importlib.resources import files

import cantools
from cantools.database.can import Database

ESWARBOT_LLC_DBC = files(__package__) / "eswarbot_llc.dbc"


@cache
def eswarbot_llc_db() -> Database:
    """The eSwarBot low-level controller's CAN database (loaded once per process)."""
    return cantools.database.load_string(ESWARBOT_LLC_DBC.read_text(), database_format="dbc")
