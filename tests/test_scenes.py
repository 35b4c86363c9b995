"""Scene configs: units convert to SI, overrides apply, errors name the field and the allowed values."""

import pytest

from scenes import ConfigError, config_json, list_presets, load_scene


def test_preset_matches_paper_table_1():
    cfg = load_scene("cnt_pdms")
    assert (cfg.pad.size_x_m, cfg.pad.size_y_m, cfg.pad.thickness_m) == pytest.approx((0.03, 0.03, 0.005))
    assert cfg.pad.youngs_modulus_pa == pytest.approx(1.85e6)
    assert cfg.sampling.sample_rate_hz == 100 and cfg.sensor.electronics.adc_bits == 14
    assert cfg.protocol.frequencies_hz == [0.1, 0.5, 1.0, 2.0]
    assert "cnt_pdms" in list_presets()


@pytest.mark.parametrize(
    "override, path, value",
    [
        ("pad.thickness_m=4 mm", ("pad", "thickness_m"), 0.004),
        ("pad.youngs_modulus_pa=2.5 MPa", ("pad", "youngs_modulus_pa"), 2.5e6),
        ("protocol.ramp_s=250 ms", ("protocol", "ramp_s"), 0.25),
        ("sensor.electronics.excitation_v=500 mV", ("sensor", "electronics", "excitation_v"), 0.5),
        ("generation.episodes=7", ("generation", "episodes"), 7),
    ],
)
def test_overrides_with_units_become_si(override, path, value):
    obj = load_scene("cnt_pdms", [override])
    for p in path:
        obj = getattr(obj, p)
    assert obj == pytest.approx(value)


@pytest.mark.parametrize(
    "override, expected",
    [
        ("pad.thikness_m=3", "unknown field 'pad.thikness_m' (did you mean 'thickness_m'?)"),
        ("padd.thickness_m=3", "unknown field 'padd'"),
        ("pad.thickness_m=5 N", "field 'pad.thickness_m' takes a value in m units; got unit 'N'"),
        ("pad.thickness_m=-1", "field 'pad.thickness_m': got -1; allowed: a finite number, 0 < value <= 0.1"),
        ("protocol.frequencies_hz=[30]", "allowed: 0 < f < 10 Hz"),
        ("sensor.electronics.filter_order=3", "must be even (0, 2, 4, 6, 8)"),
        ("sensor.electronics.filter_cutoff_hz=60", "below the Nyquist frequency 50 Hz"),
        ("protocol.amplitude_max=6 mm", "protocol.amplitude_max"),
        ("sampling.physics_timestep_s=3 ms", "a whole number of times"),
        ("sensor.hysteresis.play_weights=[0.5,0.6,0,0]", "sum to < 1"),
    ],
)
def test_errors_name_the_field(override, expected):
    with pytest.raises(ConfigError) as exc:
        load_scene("cnt_pdms", [override])
    msg = str(exc.value)
    assert expected in msg and "\n" not in msg


def test_unknown_preset_lists_allowed(tmp_path):
    with pytest.raises(ConfigError, match="allowed: .*cnt_pdms"):
        load_scene("nope")
    bad = tmp_path / "s.yaml"
    bad.write_text("pad: [1, 2\n")
    with pytest.raises(ConfigError, match="not valid YAML"):
        load_scene(bad)


def test_yaml_file_and_canonical_json(tmp_path):
    f = tmp_path / "scene.yaml"
    f.write_text("name: mine\npad:\n  thickness_m: 3 mm\n")
    cfg = load_scene(f)
    assert cfg.name == "mine" and cfg.pad.thickness_m == pytest.approx(0.003)
    assert config_json(cfg) == config_json(load_scene(f))
