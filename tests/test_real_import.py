"""Import of the Lupasic Velostat + Futek logs (../shared/real/velostat-lupasic) into a real recording."""

from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from piezotwin.cli import app
from sensors.data.real_import import (
    ImportLogError,
    import_logs,
    lupasic_pairs,
    read_calibration,
    read_log,
)
from sensors.data.recording import Recording

runner = CliRunner()
REAL = Path(__file__).resolve().parents[1].parent / "shared" / "real" / "velostat-lupasic"
if not REAL.is_dir():
    REAL = Path("/work/shared/real/velostat-lupasic")
SENSOR = REAL / "velostat_data" / "pike1" / "exp_pike1_sensor1_exp1.txt"
FORCE = REAL / "futek_data" / "pike1" / "exp_pike1_sensor1_exp1.txt"
CAL = REAL / "futek_data" / "futek_calibration.txt"
needs_real = pytest.mark.skipif(not SENSOR.is_file(), reason="real Lupasic logs not present")


@needs_real
def test_import_pike1_cli(tmp_path):
    out = tmp_path / "pike1.h5"
    res = runner.invoke(app, ["import", str(SENSOR), str(FORCE), "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert "143 Hz common clock" in res.output and "force" in res.output
    with Recording(out) as rec:
        assert rec.attrs["source"] == "real" and rec.sensor_attrs["family"] == "velostat"
        ep = rec.episode_ids[0]
        a = rec.episode_attrs(ep)
        t, f, s = rec.read(ep, "time"), rec.read(ep, "force"), rec.read(ep, "sensor")
        assert rec.units(ep, "force") == "N" and rec.units(ep, "time") == "s" and rec.units(ep, "sensor") == "raw"
        assert rec.dim_names(ep, "sensor") == ("time", "channel") and s.shape == (len(t), 1)
        assert len(rec.read(ep, "sensor_native")) == 14733 and len(rec.read(ep, "force_native")) == 26339
    assert 142 < a["sensor_rate_hz"] < 144 and 250 < a["force_rate_hz"] < 262
    assert 100 < a["duration_s"] < 106 and abs(a["start_offset_s"]) < 0.02
    assert np.allclose(np.diff(t), 1 / 143.0) and np.all(np.isfinite(f)) and np.all(np.isfinite(s))
    assert 10.5 < f.max() < 11.5 and f.min() >= 0
    # pressed: force up, Velostat reading (resistance) down
    pressed = f > 0.5 * f.max()
    assert np.median(s[pressed, 0]) < 0.2 * np.median(s[f < 0.3, 0])


@needs_real
def test_calibration_file():
    slope, offset, resid = read_calibration(CAL)
    assert 0.006 < slope < 0.0066 and abs(offset) < 0.1 and resid < 0.02  # kg per count


def _logs(tmp_path, force_lines):
    s = tmp_path / "sensor.txt"
    s.write_text("".join(f"{1600 - 10 * i} {100 + i * 0.007}\n" for i in range(200)))
    f = tmp_path / "force.txt"
    f.write_text("".join(force_lines))
    return s, f


def test_counts_and_kg_units(tmp_path):
    s, f = _logs(tmp_path, [f"{i % 50} {100 + i * 0.004}\n" for i in range(350)])
    cal = tmp_path / "cal.txt"
    cal.write_text("0 0\n100 1.0\n")
    out = import_logs(s, f, tmp_path / "c.h5", force_units="counts", calibration=cal, rate_hz=100)
    with Recording(out) as rec:
        ep = rec.episode_ids[0]
        assert rec.read(ep, "force_native").max() == pytest.approx(49 * 0.01 * 9.80665, rel=1e-5)
        assert rec.episode_attrs(ep)["calibration"]["kg_per_count"] == pytest.approx(0.01)
    with pytest.raises(ImportLogError, match="need a calibration"):
        import_logs(s, f, tmp_path / "d.h5", force_units="counts")


@pytest.mark.parametrize(
    "bad, needle",
    [
        ("0.5 100.1 7\n", "force.txt:3: malformed line (expected 'force unix_time_s', got 3 fields)"),
        ("zero 100.1\n", "force.txt:3: malformed line (not two numbers)"),
        ("nan 100.1\n", "force.txt:3: malformed line (non-finite"),
        ("0.5 99.0\n", "force.txt:3: time goes backwards"),
    ],
)
def test_malformed_line_one_line_exit_2(tmp_path, bad, needle):
    s, f = _logs(tmp_path, ["0.1 100.0\n", "0.2 100.05\n", bad, "0.3 100.2\n"])
    out = tmp_path / "m.h5"
    res = runner.invoke(app, ["import", str(s), str(f), "-o", str(out)])
    assert res.exit_code == 2, res.output
    assert needle in res.output.replace("\n", "") and res.output.count("error:") == 1
    assert not out.exists()


def test_missing_file_and_no_overlap(tmp_path):
    s, f = _logs(tmp_path, [f"1 {200 + i}\n" for i in range(5)])
    res = runner.invoke(app, ["import", str(s), str(tmp_path / "nope.txt"), "-o", str(tmp_path / "x.h5")])
    assert res.exit_code == 2 and "cannot read" in res.output
    res = runner.invoke(app, ["import", str(s), str(f), "-o", str(tmp_path / "x.h5")])
    assert res.exit_code == 2 and "do not overlap" in res.output
    with pytest.raises(ImportLogError):
        read_log(s.parent / "nope.txt")


@needs_real
def test_import_whole_folder_one_episode_per_run(tmp_path):
    pairs = lupasic_pairs(REAL)
    assert len(pairs) == 16 and all(s.name == f.name for s, f in pairs)
    res = runner.invoke(app, ["import", "--dir", str(REAL), "-o", str(tmp_path / "all.h5")])
    assert res.exit_code == 0, res.output
    with Recording(tmp_path / "all.h5") as rec:
        assert len(rec.episode_ids) == 16 and "exp_pike1_force_40_sensor1_exp2" in rec.episode_ids
        rates = {rec.episode_attrs(ep)["rate_hz"] for ep in rec.episode_ids}
        peak = max(rec.episode_attrs(ep)["force_max_n"] for ep in rec.episode_ids)
    assert rates == {143.0} and 44 < peak < 46
    res = runner.invoke(app, ["import", str(SENSOR), "--dir", str(REAL), "-o", str(tmp_path / "x.h5")])
    assert res.exit_code == 2 and "either" in res.output


# ------------------------------------------------------------------ any column log (sensors/data/column_import.py)
from sensors.data.column_import import (
    LAYOUTS,
    import_columns,
    load_spec,
    read_weight_calibration,
)

SWEEP = REAL / "speed_sweep"
TAMS = REAL.parent / "tams-array" / "calibration"


def _csv_spec(**kw):
    spec = {"name": "t", "family": "generic", "input": "sensor", "target": "force",
            "streams": [{"name": "log", "glob": "*.csv", "sample_rate_hz": 50.0, "header_lines": 1,
                         "columns": [{"index": 0, "name": "sensor", "units": "counts"},
                                     {"index": 1, "name": "force", "units": "N",
                                      "calibration": {"points": [[100, 0.0], [300, 2.0]]}},
                                     {"index": 2, "name": "label", "role": "event"}]}]}
    spec["streams"][0].update(kw)
    return spec


def test_csv_two_point_stated_rate_events(tmp_path):
    d = tmp_path / "d"
    d.mkdir()
    (d / "run1.csv").write_text("sensor,force,label\n10,100\n20,200,touch\n30,300\n40,400,lift\n")
    p = import_columns(d, _csv_spec(), tmp_path / "o.h5")
    with Recording(p) as rec:
        (ep,) = rec.episode_ids
        f = np.asarray(rec.read(ep, "force"))
        np.testing.assert_allclose(f, [0, 1, 2, 3], atol=1e-6)  # two-point line (100 -> 0 N, 300 -> 2 N)
        np.testing.assert_allclose(np.asarray(rec.read(ep, "time")), np.arange(4) / 50.0)
        a = rec.episode_attrs(ep)
        assert [e["label"] for e in a["events"]] == ["touch", "lift"]
        assert a["events"][0]["time_s"] == pytest.approx(0.02)


def test_uncertain_period_recorded(tmp_path):
    d = tmp_path / "d"
    d.mkdir()
    (d / "a.csv").write_text("h\n1,100\n2,200\n3,300\n")
    p = import_columns(d, _csv_spec(sample_rate_hz=None, sample_period_range_s=[0.01, 0.02]), tmp_path / "o.h5")
    with Recording(p) as rec:
        a = rec.episode_attrs(rec.episode_ids[0])
        assert a["rate_hz"] == pytest.approx(1 / 0.015)
        assert list(a["log_sample_period_range_s"]) == [0.01, 0.02] and a["time_uncertain"]


@pytest.mark.parametrize("body,needle", [("h\n1,100\nx,200\n", "a.csv:3: column 0 (sensor) is not a number"),
                                        ("h\n1,100\n2\n", "a.csv:3: malformed line (expected at least 2")])
def test_column_bad_line_one_line_exit_2(tmp_path, body, needle):
    import yaml

    d = tmp_path / "d"
    d.mkdir()
    (d / "a.csv").write_text(body)
    spec = tmp_path / "spec.yaml"
    spec.write_text(yaml.safe_dump(_csv_spec()))
    res = CliRunner().invoke(app, ["import", "--spec", str(spec), str(d), "-o", str(tmp_path / "o.h5")])
    assert res.exit_code == 2, res.output
    assert needle in res.output and len(res.output.strip().splitlines()) == 1
    assert not (tmp_path / "o.h5").exists()


def test_bad_spec_one_line(tmp_path):
    spec = tmp_path / "s.yaml"
    spec.write_text("streams: [{name: a, glob: '*', columns: [{index: 0, name: sensor}]}]\n")
    res = CliRunner().invoke(app, ["import", "--spec", str(spec), str(tmp_path), "-o", str(tmp_path / "o.h5")])
    assert res.exit_code == 2 and "s.yaml" in res.output and len(res.output.strip().splitlines()) == 1


def test_weight_calibration_file(tmp_path):
    f = tmp_path / "c.txt"
    f.write_text("no weight: 1000\n20g weight: 3000\ntip: 6mm cylinder\nresistance: 10kOhm\n")
    assert read_weight_calibration(f) == [(1000.0, 0.0), (3000.0, 0.02)]
    f.write_text("no weight: 1000\n")
    with pytest.raises(ImportLogError, match="c.txt: a calibration needs at least 2"):
        read_weight_calibration(f)


@pytest.mark.skipif(not SWEEP.is_dir(), reason="speed sweep logs not present")
def test_import_speed_sweep_layout(tmp_path):
    res = CliRunner().invoke(app, ["import", "--spec", "lupasic-sweep", str(SWEEP), "-o", str(tmp_path / "s.h5")])
    assert res.exit_code == 0, res.output
    with Recording(tmp_path / "s.h5") as rec:
        assert len(rec.episode_ids) == 9
        ep = "speed_0.01-attempt_0"
        a = rec.episode_attrs(ep)
        labels = [e["label"] for e in a["events"]]
        assert labels[0] == "start_exp" and "touch_grd" in labels and "go_up_roll" in labels
        assert 100 < a["sensor_rate_hz"] < 200 and a["force_max"] > 10
        assert np.asarray(rec.read(ep, "sensor")).shape[1] == 1
        # the load cell's log pauses from touch_grd to go_up_roll (~3.2 s, the arm on the ground): those stretches
        # stay empty on the common clock, not a straight line drawn from the touch to the lift-off
        gaps = np.asarray(a["force_gaps_s"])
        assert len(gaps) >= 20 and 3.0 < gaps[:, 1].max() < 3.5
        f, t = np.asarray(rec.read(ep, "force")), np.asarray(rec.read(ep, "time"))
        g0, gl = gaps[np.argmax(gaps[:, 1])]
        inside = (t > g0 + 0.05) & (t < g0 + gl - 0.05)
        assert inside.sum() > 400 and np.isnan(f[inside]).all()
    assert "stretch(es) without a sample" in res.output


@pytest.mark.skipif(not TAMS.is_dir(), reason="TAMS logs not present")
def test_import_tams_layout(tmp_path):
    res = CliRunner().invoke(app, ["import", "--spec", "tams", str(TAMS), "-o", str(tmp_path / "t.h5")])
    assert res.exit_code == 0, res.output
    with Recording(tmp_path / "t.h5") as rec:
        assert sorted(rec.episode_ids) == ["10k-nosil-cylindertip", "10k-thicksil-cylindertip", "10k-thinsil-cylindertip"]
        a = rec.episode_attrs("10k-nosil-cylindertip")
        assert a["reference_resistor_ohm"] == 10_000.0
        assert list(a["log_sample_period_range_s"]) == [0.01, 0.02]
        f = np.asarray(rec.read("10k-nosil-cylindertip", "force"))
        assert abs(np.median(f[:20])) < 0.02 and 0.5 < f.max() < 2.0  # N, from the two-point calibration
        assert rec.sensor_attrs["adc_bits"] == 10


def test_layouts_validate():
    for name in LAYOUTS:
        assert load_spec(name).name == name


def _ms_grams_spec(**col):
    """A user's own log: a time column in ms, force in grams off a scale, the reading in ADC counts."""
    return {"name": "fsr", "family": "divider", "input": "sensor", "target": "force",
            "streams": [{"name": "log", "glob": "*.csv", "header_lines": 1, "delimiter": "comma",
                         "columns": [{"index": 0, "name": "t", "role": "time", "units": "ms", **col},
                                     {"index": 1, "name": "force", "units": "g"},
                                     {"index": 2, "name": "sensor", "units": "counts"}]}]}


def test_a_time_column_in_ms_and_grams_of_force_read_as_a_user_writes_them(tmp_path):
    """`units: ms` on a time column is its time unit (it was ignored: the ms read as s gave a 0 Hz clock and a
    ZeroDivisionError); the target in grams (a scale's reading) is written in N (x 9.80665e-3), the logged unit kept
    as an attribute."""
    d = tmp_path / "d"
    d.mkdir()
    (d / "r.csv").write_text("time_ms,scale_g,adc\n" + "".join(f"{5 * k},{100.0 * k},{10 * k}\n" for k in range(50)))
    p = import_columns(d, _ms_grams_spec(), tmp_path / "o.h5")
    with Recording(p) as rec:
        (ep,) = rec.episode_ids
        assert rec.episode_attrs(ep)["rate_hz"] == 200.0 and rec.units(ep, "force") == "N"
        np.testing.assert_allclose(np.asarray(rec.read(ep, "force"))[:3], [0.0, 0.980665, 1.96133], rtol=1e-6)
        assert rec.episode_attrs(ep)["force_units_logged"] == "g"


def test_import_notes_a_rising_reading_without_its_full_scale(tmp_path):
    """A reading that rises with force (the FSR above its pull-down) imported without adc_full_scale: the import
    says at once that `fit` and `sim2real` will need it (they refuse it later); with it, no note."""
    import yaml

    d = tmp_path / "d"
    d.mkdir()
    rows = [(5 * k, 500.0 * (k % 40 > 20), 10 + 800 * (k % 40 > 20)) for k in range(400)]
    (d / "r.csv").write_text("t,g,adc\n" + "".join(f"{a},{b},{c}\n" for a, b, c in rows))
    for attrs, noted in (({}, True), ({"adc_full_scale": 1023}, False)):
        f = tmp_path / "spec.yaml"
        f.write_text(yaml.safe_dump({**_ms_grams_spec(), "sensor_attrs": attrs}))
        res = CliRunner().invoke(app, ["import", "--spec", str(f), str(d), "-o", str(tmp_path / f"o{noted}.h5")])
        assert res.exit_code == 0, res.output
        assert ("the reading rises with force in 1 episode(s) (r)" in res.output) == noted, res.output


@pytest.mark.parametrize("spec,needle", [
    (_ms_grams_spec(time_units="s"), "time column 't': units 'ms' and time_units 's' differ"),
    (_ms_grams_spec(units="min"), "time column 't': units 'min' (allowed: s, ms, us, ns)"),
    ({**_ms_grams_spec(), "streams": [{**_ms_grams_spec()["streams"][0], "columns": [
        {"index": 0, "name": "t", "role": "time", "units": "ms"}, {"index": 1, "name": "force", "units": "counts"},
        {"index": 2, "name": "sensor", "units": "counts"}]}]}, "target 'force': units 'counts' is not a force"),
])
def test_a_time_or_force_unit_that_does_not_fit_is_one_line(tmp_path, spec, needle):
    import yaml

    f = tmp_path / "spec.yaml"
    f.write_text(yaml.safe_dump(spec))
    res = CliRunner().invoke(app, ["import", "--spec", str(f), str(tmp_path), "-o", str(tmp_path / "o.h5")])
    assert res.exit_code == 2 and needle in res.output and len(res.output.strip().splitlines()) == 1, res.output


def test_a_clock_of_zero_rate_is_one_line(tmp_path):
    """A time column whose unit is wrong (ms read as s: 0.2 samples per second) names the file, not a traceback."""
    d = tmp_path / "d"
    d.mkdir()
    (d / "r.csv").write_text("time_ms,scale_g,adc\n" + "".join(f"{5 * k},{100.0 * k},{10 * k}\n" for k in range(50)))
    with pytest.raises(ImportLogError, match=r"r.csv: its time column gives 0.2 samples per second"):
        import_columns(d, _ms_grams_spec(units="s"), tmp_path / "o.h5")


def test_a_stalled_stream_is_left_empty_not_bridged_by_a_line(tmp_path):
    """Two streams on one clock: where one has no sample for more than 1 s (sensors.data.resample.MAX_GAP_S), the
    common clock holds NaN there and the stretch is recorded; a shorter pause is interpolated as before."""
    from sensors.serial.capture import gaps_of, interp_onto

    t = np.concatenate([np.arange(0, 2, 0.01), np.arange(5, 6, 0.01), np.arange(6.5, 7, 0.01)])
    y = t.copy()
    grid = np.arange(0, 7, 0.005)
    out = interp_onto(grid, t, y, 1.0)[:, 0]
    assert np.isnan(out[(grid > 2.0) & (grid < 4.99)]).all()  # 3 s without a sample
    mid = (grid > 6.0) & (grid < 6.5)  # 0.5 s: bridged
    np.testing.assert_allclose(out[mid], grid[mid], atol=1e-9)
    np.testing.assert_allclose(out[grid <= 1.99], grid[grid <= 1.99], atol=1e-9)
    assert [[round(a, 2), round(b, 2)] for a, b in gaps_of(t, 1.0)] == [[1.99, 3.01]]
    inside = grid <= t[-1]
    np.testing.assert_allclose(interp_onto(grid, t, y)[inside, 0], np.interp(grid[inside], t, y))  # no max_gap_s: as before


def test_a_resistor_in_a_file_name_is_read_in_any_usual_writing(tmp_path):
    """name_attrs of kind "resistance" (the TAMS layout's reference resistor): 10k, 4.7k, 4k7 (IEC 60062 RKM), 470R,
    1M5 are read in ohm; a file whose name does not give it is imported without the attribute, and the summary
    line says so."""
    from sensors.data.column_import import parse_resistance

    assert [parse_resistance(t) for t in ("10k", "4.7k", "4k7", "2K2", "470R", "1M5", "x7")] == \
        [1e4, 4.7e3, 4.7e3, 2.2e3, 470.0, 1.5e6, None]
    d = tmp_path / "cal"
    d.mkdir()
    (d / "calibration2.txt").write_text("no weight: 1660130\n20g weight: 1667333\ntip: 6mm\nresistance: 10kOhm\n")
    body = "".join(f"{1660130 + 100 * (k % 30)} {5000 - 100 * (k % 30)}\n" for k in range(300))
    for name in ("4k7-nosil-cylindertip.1614926403.33.txt", "nores-nosil-cylindertip.1614926404.10.txt"):
        (d / name).write_text(body)
    res = CliRunner().invoke(app, ["import", "--spec", "tams", str(d), "-o", str(tmp_path / "t.h5")])
    assert res.exit_code == 0, res.output
    with Recording(tmp_path / "t.h5") as rec:
        a = {ep: rec.episode_attrs(ep) for ep in rec.episode_ids}
    got = {ep: v.get("reference_resistor_ohm") for ep, v in a.items()}
    assert sorted(got.values(), key=str) == [4700.0, None], got
    assert "not in the file name: reference_resistor_ohm" in res.output
