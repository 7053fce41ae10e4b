"""Rig-file validation: every error names its field in one line."""

from __future__ import annotations

import pytest

from bench.core import config
from bench.errors import BadInput


def test_shipped_mock_rig_loads():
    cfg = config.load("mock")
    assert cfg.driver == "mock" and cfg.rate_hz == 3000
    assert cfg.T_s == pytest.approx(1 / 3000)
    assert cfg.motor.L_m == 0.341 and cfg.motor.Z_p == 2


@pytest.mark.parametrize(
    "data, field",
    [
        ({"rig": {"driver": "warp"}}, "rig.driver"),
        ({"rig": {"rate_hz": 1e6}}, "rig.rate_hz"),
        ({"rig": {"rate_hz": "fast"}}, "rig.rate_hz"),
        ({"rig": {"colour": 1}}, "rig.colour"),
        ({"rig": {}, "limits": {"I_trip": -1.0}}, "limits.I_trip"),
        ({"rig": {}, "limits": {"I_max": 20.0}}, "limits.I_max"),
        ({"rig": {}, "limits": {"I_mux": 20.0}}, "limits.I_mux"),
        ({"rig": {}, "motor": {"L_m": 0.4}}, "motor.L_m"),
        ({"rig": {}, "motor": {"R_s": 0.0}}, "motor.R_s"),
        ({"rig": {}, "motor": {"Z_p": 1.5}}, "motor.Z_p"),
        ({"rig": {}, "extra": {}}, "extra"),
        ({}, "rig"),
    ],
)
def test_bad_rig_data_names_the_field(data, field):
    with pytest.raises(BadInput) as exc:
        config.parse(data)
    assert exc.value.field == field
    assert "\n" not in str(exc.value)


def test_unknown_rig_name_lists_known(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(BadInput, match="rig: no rig file 'nowhere'.*mock"):
        config.load("nowhere")


def test_invalid_toml_is_a_bad_input(tmp_path):
    p = tmp_path / "broken.toml"
    p.write_text("[rig\nname=")
    with pytest.raises(BadInput, match="not valid TOML"):
        config.load(str(p))
