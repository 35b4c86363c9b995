"""Import of the Lupasic Velostat + Futek logs (../shared/real/velostat-lupasic) into a real recording."""

from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from piezotwin.cli import app
from sensors.data.real_import import ImportLogError, import_logs, lupasic_pairs, read_calibration, read_log
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
