"""What the commands print is true and whole (issue 17, item 9): no Warp CUDA-driver warning on a CPU machine,
tables keep whole names when piped, generate summarises the whole dataset, show's default file name is the
one the docs give."""

from __future__ import annotations

import os

import pytest
from typer.testing import CliRunner

from piezotwin.cli import app

runner = CliRunner()
FAST = ["--set", "protocol.frequencies_hz=[2.0]", "--set", "protocol.cycles=1", "--set", "pad.taxels_x=5",
        "--set", "pad.taxels_y=5", "--set", "generation.episodes_per_shard=2", "--episodes", "3"]


@pytest.fixture(scope="module")
def generated(tmp_path_factory):
    out = tmp_path_factory.mktemp("gen") / "ds"
    res = runner.invoke(app, ["generate", "cnt_pdms", "-o", str(out)] + FAST)
    assert res.exit_code == 0, res.output
    return out, res.output


def test_generate_summarises_the_whole_dataset(generated):
    out, text = generated
    assert "3 episodes in 2 shards" in text and "ranges over all 2 shards" in text
    assert "episodes=2" not in text  # the old summary of shard 0 only


def test_tables_keep_whole_names_when_piped(generated):
    out, text = generated
    assert "resistance_measured" in text and "…" not in text
    res = runner.invoke(app, ["inspect", str(out / "shard-00000.h5")])
    assert res.exit_code == 0 and "resistance_measured" in res.output and "…" not in res.output


def test_init_warp_drops_only_the_no_driver_warning(monkeypatch, capfd):
    from sensors import warp_setup

    def fake_init():
        os.write(2, b"Warp CUDA warning: Could not find or load the NVIDIA CUDA driver. GPU execution will not be available.\n")
        os.write(2, b"something else Warp says\n")

    monkeypatch.setattr(warp_setup, "_done", False)
    monkeypatch.setattr(warp_setup.wp, "init", fake_init)
    warp_setup.init_warp()
    err = capfd.readouterr().err
    assert "CUDA driver" not in err and "something else Warp says" in err


def test_show_default_name_and_export_layout(offscreen, generated, tmp_path, monkeypatch):
    out, _ = generated
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.chdir(tmp_path)
    res = runner.invoke(app, ["show", str(out), "-e", "1", "-f", "pressure", "--size", "160x120"])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "shard-00000-ep-000001-pressure.png").is_file()  # docs/visualization.md's name
    res = runner.invoke(app, ["export", str(out), "-e", "1", "-o", str(tmp_path / "vtk"), "--stride", "50"])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "vtk" / "ep-000001.pvd").is_file()
    assert (tmp_path / "vtk" / "ep-000001" / "body_000000.vtu").is_file()
    assert (tmp_path / "vtk" / "ep-000001" / "indenter_000000.vtu").is_file()


def test_parallel_shard_summaries_equal_the_serial_read(generated):
    # the summary's reader processes (large datasets on many cores) give the same dicts as reading here
    from piezotwin.common import _summaries

    out, _ = generated
    files = sorted(out.glob("shard-*.h5"))
    assert len(files) == 2
    serial = _summaries(files, parallel=False)
    assert _summaries(files, parallel=True) == serial
    assert [s["n_episodes"] for s in serial] == [2, 1]


def test_generate_summary_is_the_manifests_merge_of_the_stored_summaries(generated, tmp_path):
    # the end of `generate` prints the manifest's summary (the writers' stored summaries merged, no shard opened),
    # equal to reading every shard's data; a manifest without one (an older piezotwin) sends it back to reading
    import json

    from piezotwin.common import _summaries
    from sensors.data.manifest import read_manifest
    from sensors.data.recording import merge_summaries

    out, text = generated
    files = sorted(out.glob("shard-*.h5"))
    read = merge_summaries(_summaries(files, parallel=False))
    stored = read_manifest(out)["summary"]
    assert json.loads(json.dumps(read)) == stored
    assert stored["n_samples"] == sum(s["n_samples"] for s in _summaries(files, parallel=False))
    assert f"{stored['n_samples']} samples" in text
    assert "(25,)" in text and "[25]" not in text  # frame shapes print as inspect prints them (JSON gives lists)
    old = tmp_path / "old"
    old.mkdir()
    m = json.loads((out / "manifest.json").read_text())
    del m["summary"]
    (old / "manifest.json").write_text(json.dumps(m))
    for f in files:
        (old / f.name).symlink_to(f)
    from piezotwin import common

    common.console.record = True
    try:
        common._print_dataset_summary(old)
        again = common.console.export_text()
    finally:
        common.console.record = False
    assert f"{stored['n_samples']} samples" in again and "ranges over all 2 shards" in again


def test_generate_path_leaves_out_torch_learn_and_scipy_signal():
    # what `piezotwin generate` imports before its first episode on the GPU feed: the CLI, the engine choice,
    # the executors, the feed and the sensor chains; none of them may pull in torch, learn or scipy.signal
    # (~1 s of scipy.signal import that the GPU path never calls; the numpy noise path imports it where used), and
    # the engine choice finds mujoco_warp without importing it (2.5-4 s; the physics processes import it)
    import subprocess
    import sys

    code = ("import sys, piezotwin.cli, simulate.generation.choice, simulate.generation.executors, "
            "simulate.generation.feed, simulate.generation.run, sensors.electronics, sensors.registry; "
            "from simulate.contact.mujoco_warp import available; available(); "
            "print(sorted(m for m in ('torch', 'learn', 'scipy.signal', 'pyvista', 'matplotlib', 'mujoco_warp') "
            "if m in sys.modules))")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                         env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})
    assert res.returncode == 0, res.stderr[-2000:]
    assert res.stdout.strip().splitlines()[-1] == "[]"
