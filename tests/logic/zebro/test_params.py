"""The Zebro controllers' parameters: every reading of an ambiguity is a parameter with its choices checked, and the
docs name each of them."""

from __future__ import annotations

from pathlib import Path

import pytest

from swarm_logic.families.zebro.immature import ZebroImmature
from swarm_logic.families.zebro.mature import ZebroMature
from swarm_logic.families.zebro.silent import ZebroSilent

DOC = Path(__file__).resolve().parents[3] / "docs" / "zebro-algorithms.md"


@pytest.mark.parametrize("cls", [ZebroSilent, ZebroImmature, ZebroMature])
def test_choices_are_checked(cls) -> None:
    for name, allowed in cls.choices.items():
        assert cls.defaults[name] in allowed
        assert cls.resolve({name: allowed[-1]})[name] == allowed[-1]
        with pytest.raises(ValueError, match=name):
            cls.resolve({name: "no-such-reading"})
    with pytest.raises(ValueError):
        cls.resolve({"no_such_parameter": 1})


def test_the_docs_name_every_reading() -> None:
    text = DOC.read_text()
    for cls in (ZebroSilent, ZebroImmature, ZebroMature):
        for name, allowed in cls.choices.items():
            assert f"`{name}`" in text, name
            for value in allowed:
                assert f"`{value}`" in text, (name, value)


def test_a_robot_without_the_zebro_devices_is_refused() -> None:
    import numpy as np

    from swarm_logic.clock import SteppedClock
    from swarm_logic.robot import Robot

    robot = Robot(3, SteppedClock(), None, np.random.default_rng(0))
    with pytest.raises(KeyError, match="uwb_radio"):
        ZebroMature().init(robot)
