"""Every subcommand refuses a bad count or duration at parse time, naming the flag, before anything starts."""

from __future__ import annotations

import argparse

import pytest

from bridge.tools import argtypes
from bridge.tools.cli import build_parser


@pytest.mark.parametrize("argv, flag", [
    (["campaign", "flake", "--runs", "0", "tests"], "--runs"),
    (["campaign", "orphans", "--trials", "-3"], "--trials"),
    (["campaign", "orphans", "--speed", "0"], "--speed"),
    (["campaign", "concurrency", "--sessions", "two"], "--sessions"),
    (["campaign", "soak", "--sim-hours", "0"], "--sim-hours"),
    (["campaign", "soak", "--robots", "0"], "--robots"),
    (["fuzz", "--runs", "0"], "--runs"),
    (["run", "hil_configs/demo.toml", "--speed", "-1"], "--speed"),
])
def test_a_bad_value_is_refused_naming_its_flag(argv: list[str], flag: str,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as e:
        build_parser().parse_args(argv)
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert f"argument {flag}" in err and "Traceback" not in err


def test_the_types_accept_their_good_values_and_say_why_they_refuse() -> None:
    assert argtypes.at_least_one("7") == 7
    assert argtypes.positive("0.5") == 0.5
    assert argtypes.speed("max") == "max" and argtypes.speed("2") == 2.0
    assert argtypes.numbers(int, 1, "1,2")("1,4") == [1, 4]
    for parse, bad, why in [(argtypes.at_least_one, "0", "must be >= 1"), (argtypes.positive, "nan", "must be > 0"),
                            (argtypes.numbers(float, 0, "0.2,1"), "0.2,-1", "each must be >= 0")]:
        with pytest.raises(argparse.ArgumentTypeError, match=why):
            parse(bad)
