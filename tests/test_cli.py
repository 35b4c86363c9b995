"""The command line: one-line errors with exit code 2 and nothing written; generate -> inspect round trip."""

import pytest
from typer.testing import CliRunner

from piezotwin.cli import app
from sensors.data.recording import Recording

runner = CliRunner()
FAST = ["--set", "protocol.frequencies_hz=[2.0]", "--set", "protocol.cycles=1", "--set", "pad.taxels_x=5",
        "--set", "pad.taxels_y=5", "--set", "generation.episodes_per_shard=2"]


@pytest.mark.parametrize(
    "args, needle",
    [
        (["generate", "cnt_pdm"], "unknown preset 'cnt_pdm'"),
        (["generate", "cnt_pdms", "--set", "pad.thikness_m=3"], "did you mean 'thickness_m'"),
        (["generate", "cnt_pdms", "--set", "pad.thickness_m=5 N"], "allowed: cm, m, mm"),
        (["generate", "cnt_pdms", "--set", "protocol.duration_s=-1"], "protocol.duration_s"),
        (["generate", "cnt_pdms", "--set", "protocol.frequencies_hz=[30]"], "cannot be resolved"),
        (["generate", "cnt_pdms", "--set", "protocol.kind=ramp"], "protocol.kind"),
    ],
)
def test_bad_input_one_line_exit_2_nothing_written(tmp_path, args, needle):
    out = tmp_path / "ds"
    res = runner.invoke(app, args + ["-o", str(out)])
    assert res.exit_code == 2, res.output
    assert needle in res.output.replace("\n", " ")
    assert not out.exists()


def test_unwritable_output_folder(tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        import os

        if os.access(ro, os.W_OK):
            pytest.skip("running as a user who can write anywhere")
        res = runner.invoke(app, ["generate", "cnt_pdms", "-o", str(ro / "ds")])
        assert res.exit_code == 2 and "not writable" in res.output
    finally:
        ro.chmod(0o700)


def test_output_under_a_file_is_refused(tmp_path):
    f = tmp_path / "file.txt"
    f.write_text("x")
    res = runner.invoke(app, ["generate", "cnt_pdms", "-o", str(f / "ds")])
    assert res.exit_code == 2 and "is a file, not a folder" in res.output.replace("\n", " ")


def test_generate_then_inspect(tmp_path):
    out = tmp_path / "ds"
    res = runner.invoke(app, ["generate", "cnt_pdms", "-o", str(out), "--episodes", "3", "--seed", "5"] + FAST)
    assert res.exit_code == 0, res.output
    shards = sorted(out.glob("shard-*.h5"))
    assert len(shards) == 2 and (out / "manifest.json").is_file()
    with Recording(shards[0]) as rec:
        assert rec.attrs["root_seed"] == 5
        ep = rec.episode_ids[0]
        assert rec.units(ep, "force") == "N" and rec.units(ep, "resistance") == "ohm"
        assert rec.dim_names(ep, "pressure") == ("time", "taxel")
        f = rec.read(ep, "force")
        assert f.max() > 0.5  # a real press happened
        assert "<mujoco" in rec.mjcf
    res = runner.invoke(app, ["inspect", str(out)])
    assert res.exit_code == 0 and "resistance" in res.output and "ohm" in res.output
    res = runner.invoke(app, ["inspect", str(tmp_path / "nope.h5")])
    assert res.exit_code == 2
