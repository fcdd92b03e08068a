"""A wrong [[services]] table, Wi-Fi table or added device is refused naming the file, the field and the reason."""

from __future__ import annotations

from pathlib import Path

import pytest

from bridge.core.config import ConfigError, load_config
from bridge.core.plan import make_plan

BASE = """
[arena]
width_m = 4
length_m = 4
[[robots]]
profile = "eswarbot"
count = {count}
{group}
"""


def _load(tmp_path: Path, extra: str, count: int = 2, group: str = "") -> object:
    p = tmp_path / "s.toml"
    p.write_text(BASE.format(count=count, group=group) + extra)
    return load_config(p)


@pytest.mark.parametrize(
    "extra, count, message",
    [
        ('[[services]]\nkind = "nope"\nname = "a"\n', 2, r"services\[0\]\.kind: unknown service 'nope'"),
        (
            '[[services]]\nkind = "overhead_camera"\nname = "cam"\noptions = { fps = 0 }\n',
            2,
            r"services\[0\]: options\.fps: Input should be greater than 0",
        ),
        (
            '[[services]]\nkind = "overhead_camera"\nname = "cam"\noptions = { colour = 1 }\n',
            2,
            r"services\[0\]: options\.colour: Extra inputs are not permitted",
        ),
        (
            '[[services]]\nkind = "overhead_camera"\nname = "cam"\n',
            13,
            r"services\[0\]\.options\.mode: tracking tells robots apart .* 13 robots: use mode = \"noise\"",
        ),
        ('[[services]]\nkind = "overhead_camera"\nname = "r001"\n', 2, r"services\[0\]\.name: 'r001': a service name"),
        (
            '[[services]]\nkind = "global_controller"\nname = "c"\n'
            '[[services]]\nkind = "global_controller"\nname = "c"\n',
            2,
            r"services\[1\]\.name: 'c' names another service already",
        ),
        (
            '[[services]]\nkind = "global_controller"\nname = "c"\noptions = { target = [9.0, 1.0] }\n',
            2,
            r"services\[0\]\.options\.target: \(9\.0, 1\.0\) is outside the 4\.0 x 4\.0 m arena",
        ),
        (
            '[[services]]\nkind = "global_controller"\nname = "c"\noptions = { controller = "nobody" }\n',
            2,
            r"services\[0\]\.options\.controller: unknown global controller 'nobody'",
        ),
        (
            '[[services]]\nkind = "overhead_camera"\nname = "cam"\n'
            'options = { mode = "noise", noise_model = "x.json" }\n',
            2,
            r"services\[0\]\.options\.noise_model: cannot read 'x\.json'",
        ),
        ("[wifi]\nloss = 0.5\n", 2, r"wifi: loss do\(es\) not apply to mode = 'ideal'"),
        ('[wifi]\nmode = "lossy"\nloss = 1.5\n', 2, r"wifi\.loss: Input should be less than or equal to 1"),
    ],
)
def test_a_wrong_service_or_wifi_config_names_file_field_and_reason(
    tmp_path: Path, extra: str, count: int, message: str
) -> None:
    with pytest.raises(ConfigError, match=message) as e:
        _load(tmp_path, extra, count)
    assert str(e.value).startswith(str(tmp_path / "s.toml"))


def test_a_device_the_session_cannot_add_is_named(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"robots\[0\]\.devices: 'xbee' is not a device the session can add"):
        _load(tmp_path, "", group='devices = { xbee = { port = "sitl://xbee" } }')


def test_services_get_a_process_each(tmp_path: Path) -> None:
    cfg = _load(
        tmp_path,
        '[[services]]\nkind = "overhead_camera"\nname = "cam"\n[[services]]\n'
        'kind = "global_controller"\nname = "ctl"\n',
        group='devices = { sonpi_wifi = { url = "sitl://wifi" } }',
    )
    plan = make_plan(cfg)
    svc = [(p.name, p.kind, p.entities(plan.robots)) for p in plan.procs if p.kind == "service"]
    assert svc == [("svc-cam", "service", ["svc/cam"]), ("svc-ctl", "service", ["svc/ctl"])]
    assert plan.robots[0].devices == {"sonpi_wifi": {"url": "sitl://wifi"}}
