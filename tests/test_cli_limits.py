"""0 is not "unset": out-of-range numbers on the command line are one line and exit 2, nothing written, nothing
left behind; an existing -o recording is not replaced without --force (issue 17, item 7)."""

from __future__ import annotations

import numpy as np
import pytest
from typer.testing import CliRunner

from piezotwin.cli import app
from sensors.data.real_import import ImportLogError, import_logs
from sensors.data.recording import Recording

runner = CliRunner()


def _logs(tmp_path):
    s = tmp_path / "sensor.txt"
    s.write_text("".join(f"{1600 - 10 * i} {100 + i * 0.007}\n" for i in range(200)))  # ~143 Hz
    f = tmp_path / "force.txt"
    f.write_text("".join(f"{0.01 * i} {100 + i * 0.004}\n" for i in range(350)))  # 250 Hz
    return s, f


def _one_line_exit_2(res, needle: str) -> None:
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output and res.output.count("error:") == 1, res.output
    assert needle in res.output.replace("\n", ""), res.output


@pytest.mark.parametrize("rate, needle", [
    ("0", "--rate must be a finite number > 0 Hz (got 0.0"),
    ("-5", "--rate must be a finite number > 0 Hz"),
    ("nan", "--rate must be a finite number > 0 Hz"),
    ("inf", "--rate must be a finite number > 0 Hz"),
    ("1e9", "more than 10x the logs' own rates"),
])
def test_import_rate_out_of_range(tmp_path, rate, needle):
    s, f = _logs(tmp_path)
    out = tmp_path / "r.h5"
    _one_line_exit_2(runner.invoke(app, ["import", str(s), str(f), "-o", str(out), "--rate", rate]), needle)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["force.txt", "sensor.txt"]  # no r.h5, no r.h5.tmp


def test_import_rate_zero_in_the_api_is_an_error(tmp_path):
    s, f = _logs(tmp_path)
    with pytest.raises(ImportLogError, match="rate must be a finite number > 0"):
        import_logs(s, f, tmp_path / "r.h5", rate_hz=0)
    assert not (tmp_path / "r.h5").exists()


def test_import_refuses_to_overwrite_without_force(tmp_path):
    s, f = _logs(tmp_path)
    out = tmp_path / "r.h5"
    assert runner.invoke(app, ["import", str(s), str(f), "-o", str(out), "--rate", "100"]).exit_code == 0
    before = out.read_bytes()
    _one_line_exit_2(runner.invoke(app, ["import", str(s), str(f), "-o", str(out), "--rate", "50"]),
                     f"'{out}' exists; add --force to replace it")
    assert out.read_bytes() == before
    res = runner.invoke(app, ["import", str(s), str(f), "-o", str(out), "--rate", "50", "--force"])
    assert res.exit_code == 0, res.output
    with Recording(out) as rec:
        assert rec.episode_attrs(rec.episode_ids[0])["rate_hz"] == 50
    _one_line_exit_2(runner.invoke(app, ["import", str(s), str(f), "-o", str(tmp_path), "--force"]), "is a folder")


@pytest.mark.parametrize("n", ["0", "-1"])
def test_show_max_frames_must_be_positive(tmp_path, n):
    out = tmp_path / "a.gif"
    res = runner.invoke(app, ["show", str(tmp_path / "any.h5"), "--animate", "-o", str(out), "--max-frames", n])
    _one_line_exit_2(res, f"--max-frames must be >= 1 (got {n}")
    assert not out.exists()


def test_frame_indices_max_frames():
    from types import SimpleNamespace

    from simulate.pictures.render import frame_indices

    v = SimpleNamespace(n_samples=100, time_s=np.arange(100) / 10.0)
    assert len(frame_indices(v, fps=10)) == 100 and len(frame_indices(v, fps=10, max_frames=7)) == 7
    assert len(frame_indices(v, fps=10, max_frames=1)) == 1
    with pytest.raises(ValueError, match="max_frames must be >= 1"):
        frame_indices(v, fps=10, max_frames=0)
