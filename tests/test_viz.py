"""Pictures, animations, ParaView export and plots: render offscreen and check what the picture shows.

Two tiny recordings (10 x 10 taxels, one 2 Hz press each): a light press (40 um) and a hard one (150 um).
Rendering tests skip with the reason when this machine has no pyvista or no offscreen OpenGL (EGL).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from scenes import load_scene
from sensors.data.recording import Recording
from simulate.pictures.fields import FieldError, load_episode, nice_exaggeration

SMALL = (240, 176)


def _make(out: Path, amplitude_m: float, jitter_m: float = 0.004) -> Path:
    from simulate.generation.run import generate

    cfg = load_scene("cnt_pdms", [
        "protocol.frequencies_hz=[2.0]", "protocol.cycles=1", "pad.taxels_x=10", "pad.taxels_y=10",
        f"protocol.amplitude_min={amplitude_m}", f"protocol.amplitude_max={amplitude_m}",
        f"indenter.position_jitter_m={jitter_m}", "generation.episodes=2", "generation.episodes_per_shard=2",
        "generation.root_seed=3",
    ])
    generate(cfg, out, backend="numpy")
    return out / "shard-00000.h5"


@pytest.fixture(scope="module")
def recs(tmp_path_factory):
    d = tmp_path_factory.mktemp("viz")
    return {"light": _make(d / "light", 4e-5), "hard": _make(d / "hard", 1.5e-4)}


def _decode(img: np.ndarray, cmap: str, clim: tuple[float, float], tol: float = 12.0) -> np.ndarray:
    """Pixel colours -> field values through the colour map (NaN where the pixel is not a map colour)."""
    import matplotlib

    lut = (matplotlib.colormaps[cmap](np.linspace(0, 1, 256))[:, :3] * 255.0).astype(np.float64)
    px = img[..., :3].reshape(-1, 3).astype(np.float64)
    d2 = ((px[:, None, :] - lut[None, :, :]) ** 2).sum(-1)
    j = d2.argmin(1)
    vals = clim[0] + (clim[1] - clim[0]) * j / 255.0
    vals[np.sqrt(d2[np.arange(len(j)), j]) > tol] = np.nan
    return vals.reshape(img.shape[:2])


# ----------------------------------------------------------------------------- numbers (no rendering)


def test_fields_follow_the_recording(views, recs):
    v = views["hard"]
    assert v.deformation_m.shape == (v.n_samples, 100)
    assert set(v.fields) >= {"deformation", "pressure", "strain", "resistance"}
    # the single readout channel is spread over every taxel
    with Recording(recs["hard"]) as rec:
        r = rec.read(v.ep_id, "resistance")[:, 0]
    np.testing.assert_allclose(v.fields["resistance"][:, 37], r)
    assert "1 readout channel" in v.notes["resistance"]
    k = v.peak_index()
    assert v.force_n[k] == v.force_n.max() > 1.0
    assert v.index_at(float(v.time_s[k]) + 1e-4) == k
    with pytest.raises(FieldError, match="outside episode"):
        v.index_at(99.0)


def test_bad_episode_and_field(recs):
    with Recording(recs["light"]) as rec:
        with pytest.raises(FieldError, match="out of range"):
            load_episode(rec, 7)
        with pytest.raises(FieldError, match="no episode 'ep-9'"):
            load_episode(rec, "ep-9")
        with pytest.raises(FieldError, match="unknown field 'temp'"):
            load_episode(rec, 0, ["temp"])
        assert load_episode(rec, "ep-000001").ep_id == "ep-000001"


def test_nice_exaggeration():
    assert nice_exaggeration(150e-6, 5e-3) == 10.0  # 0.3 * 5 mm / 150 um = 10
    assert nice_exaggeration(151e-6, 5e-3) == 10.0  # 9.93 -> 10 (nearest, not floor)
    assert nice_exaggeration(40e-6, 5e-3) == 50.0  # 37.5 -> 50 (nearer than 20 in log scale)
    assert nice_exaggeration(100e-6, 5e-3) == 20.0  # 15 -> 20
    assert nice_exaggeration(3e-3, 5e-3) == 1.0
    assert nice_exaggeration(0.0, 5e-3) == 1.0


def test_no_pyvista_import_without_rendering():
    code = "import sys, piezotwin.cli, simulate.pictures.fields, simulate.pictures.plots; assert 'pyvista' not in sys.modules, 'eager'"
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       cwd=Path(__file__).resolve().parents[1])
    assert r.returncode == 0, r.stderr


# ----------------------------------------------------------------------------- pictures


def test_frame_is_a_picture(offscreen, views, tmp_path):
    v = views["hard"]
    img, info = offscreen.render_frame(v, "deformation", v.peak_index(), tmp_path / "f.png",
                                       offscreen.RenderOptions(window_size=SMALL))
    assert img.shape == (SMALL[1], SMALL[0], 3)
    assert (tmp_path / "f.png").stat().st_size > 2000
    background = np.all(img > 245, axis=-1)
    assert 0.15 < 1 - background.mean() < 0.95  # something drawn, not a blank or a full frame
    assert len(np.unique(img.reshape(-1, 3), axis=0)) > 200  # shaded and coloured, not flat
    assert info.exaggeration == 10.0 and info.unit == "µm"
    assert info.clim[0] == 0.0
    assert info.clim[1] == pytest.approx(v.deformation_m[v.peak_index()].max() * 1e6, rel=1e-6)


def test_harder_press_shows_a_larger_peak_where_the_indenter_is(offscreen, views):
    """Top view, flat colours, same colour range: decode the pixels back to micrometres."""
    hard_peak = float(views["hard"].deformation_m.max() * 1e6)
    clim = (0.0, hard_peak)
    peaks, infos = {}, {}
    for name in ("light", "hard"):
        v = views[name]
        opts = offscreen.RenderOptions(window_size=SMALL, view="top", lighting=False, show_indenter=False,
                                       show_text=False, clim=clim)
        img, info = offscreen.render_frame(v, "deformation", v.peak_index(), None, opts)
        vals = _decode(img[:, : int(0.8 * SMALL[0])], "viridis", clim)  # left of the scalar bar
        assert np.isfinite(vals).mean() > 0.3
        r, c = np.unravel_index(np.nanargmax(vals), vals.shape)
        peaks[name] = np.nanmax(vals)
        # the decoded peak sits under the indenter (its footprint is 10 mm of a 30 mm pad)
        ir, ic = info.indenter_px
        assert abs(r - ir) < 0.2 * SMALL[1] and abs(c - ic) < 0.2 * SMALL[1], (r, c, info.indenter_px)
        # and the corners of the pad are at rest
        assert np.nanmin(vals) < 0.05 * hard_peak
        infos[name] = info
    assert peaks["hard"] == pytest.approx(hard_peak, rel=0.03)
    assert peaks["light"] < 0.45 * peaks["hard"]
    # with its own colour range, each picture's scalar bar ends at its own peak
    for name in ("light", "hard"):
        v = views[name]
        _, info = offscreen.render_frame(v, "deformation", v.peak_index(), None,
                                         offscreen.RenderOptions(window_size=SMALL))
        assert info.clim[1] == pytest.approx(v.deformation_m.max() * 1e6, rel=1e-6)
    assert views["hard"].deformation_m.max() > 3 * views["light"].deformation_m.max()


def test_indenter_is_drawn_where_it_was(offscreen, views):
    v = views["hard"]
    k = v.peak_index()
    kw = dict(window_size=SMALL, view="top", lighting=False, show_text=False)
    with_ind, info = offscreen.render_frame(v, "deformation", k, None, offscreen.RenderOptions(**kw))
    without, _ = offscreen.render_frame(v, "deformation", k, None, offscreen.RenderOptions(show_indenter=False, **kw))
    diff = np.abs(with_ind.astype(int) - without.astype(int)).sum(-1) > 20
    assert diff.mean() > 0.02
    rows, cols = np.nonzero(diff)
    ir, ic = info.indenter_px
    assert abs(rows.mean() - ir) < 0.1 * SMALL[1] and abs(cols.mean() - ic) < 0.1 * SMALL[1]


def test_animation_gif(offscreen, views, tmp_path):
    import imageio.v3 as iio

    v = views["hard"]
    out, info = offscreen.render_animation(v, "pressure", tmp_path / "a.gif", fps=10, max_frames=6,
                                           opts=offscreen.RenderOptions(window_size=(160, 128)))
    frames = iio.imread(out, index=None)
    assert frames.shape[0] == 6 and frames.shape[1:3] == (128, 160)
    assert np.abs(frames[0].astype(int) - frames[3].astype(int)).mean() > 1.0  # the press moves
    assert info.unit == "kPa" and info.clim[1] == pytest.approx(v.fields["pressure"].max() / 1e3, rel=1e-6)


# ----------------------------------------------------------------------------- export


def test_export_round_trip(offscreen, views, recs, tmp_path):
    import pyvista as pv

    from simulate.pictures.export import export_episode
    from simulate.pictures.geometry import make_geometry

    v = views["hard"]
    pvd = export_episode(v, tmp_path / "vtk", stride=5)
    reader = pv.get_reader(str(pvd))
    np.testing.assert_allclose(reader.time_values, v.time_s[::5], atol=1e-12)
    k = v.peak_index() // 5 * 5
    reader.set_active_time_value(float(v.time_s[k]))
    blocks = reader.read()
    body = blocks[0]
    assert body.n_cells > 0 and blocks[1].n_points > 0  # the indenter came along
    top = make_geometry(v).taxel_points()
    ids = [body.find_closest_point(p) for p in top]
    np.testing.assert_allclose(body.points[ids], top, atol=1e-9)
    np.testing.assert_allclose(body.point_data["deformation"][ids], v.deformation_m[k], rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(body.point_data["pressure"][ids], v.fields["pressure"][k], rtol=1e-6)
    np.testing.assert_allclose(body.point_data["displacement"][ids, 2], -v.deformation_m[k], rtol=1e-6, atol=1e-12)
    assert float(body.field_data["force"][0]) == pytest.approx(v.force_n[k], rel=1e-6)
    # the indenter's lowest point is where the recording put it (true scale)
    assert blocks[1].bounds[4] == pytest.approx(v.position_m[k, 2], abs=1e-9)


# ----------------------------------------------------------------------------- command line


def test_cli_show_export_plot_and_bad_input(offscreen, recs, tmp_path, monkeypatch):
    from piezotwin.cli import app

    runner = CliRunner()
    rec = str(recs["hard"])
    bad = [
        (["show", str(tmp_path / "nope.h5")], "does not exist"),
        (["show", rec, "--field", "temp"], "unknown field 'temp'"),
        (["show", rec, "--episode", "9"], "out of range"),
        (["show", rec, "--time", "50"], "outside episode"),
        (["show", rec, "--animate", "-o", str(tmp_path / "a.avi")], "--animate needs"),
        (["show", rec, "-o", str(tmp_path / "a.jpg")], "must end in .png"),
        (["export", rec, "--episode", "-1", "-o", str(tmp_path / "x")], "out of range"),
        (["plot", rec, "--field", "temp"], "unknown field"),
    ]
    for args, needle in bad:
        res = runner.invoke(app, args)
        assert res.exit_code == 2, (args, res.output)
        assert needle in res.output.replace("\n", " "), (args, res.output)
        assert res.output.strip().count("error:") == 1
    out = tmp_path / "s.png"
    res = runner.invoke(app, ["show", rec, "-e", "1", "-f", "strain", "-o", str(out), "--size", "200x150"])
    assert res.exit_code == 0, res.output
    assert out.stat().st_size > 1000 and "%" in res.output
    # no display and no -o: a PNG appears in the working folder, nothing to do for the user
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.chdir(tmp_path)
    res = runner.invoke(app, ["show", rec, "--size", "160x120"])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "shard-00000-ep-000000-deformation.png").is_file()
    res = runner.invoke(app, ["export", rec, "-o", str(tmp_path / "vtk"), "--stride", "10"])
    assert res.exit_code == 0 and (tmp_path / "vtk" / "ep-000000.pvd").is_file()
    res = runner.invoke(app, ["plot", rec, "-o", str(tmp_path / "p.png")])
    assert res.exit_code == 0 and (tmp_path / "p.png").stat().st_size > 5000


# ----------------------------------------------------------------------------- plots


def test_loading_mask_and_loop_colours(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    from simulate.pictures import plots

    d = np.concatenate([np.linspace(0, 1, 11), np.linspace(1, 0.5, 6)[1:], np.full(3, 0.5), np.linspace(0.5, 1, 6)[1:]])
    m = plots.loading_mask(d)
    assert m[:11].all() and not m[11:16].any() and not m[16:19].any() and m[19:].all()
    fig, ax = plots.figure()
    plots.hysteresis_loop(ax[0, 0], d * 2, d, d)
    colours = [ln.get_color() for ln in ax[0, 0].lines]
    assert colours == [plots.LOADING_COLOR, plots.UNLOADING_COLOR, plots.LOADING_COLOR]
    labels = [ln.get_label() for ln in ax[0, 0].lines]
    assert labels[:2] == ["loading", "unloading"] and labels[2].startswith("_")
    plots.save(fig, tmp_path / "l.png")


def test_taxel_map_and_error_map_place_values(tmp_path):
    from simulate.pictures import plots

    xy = np.array([[x, y] for y in (-1e-3, 1e-3) for x in (-2e-3, 0.0, 2e-3)])  # 3 x 2 grid, x fastest
    vals = np.arange(6.0)
    fig, ax = plots.figure(1, 2, size=(8, 3))
    plots.taxel_map(ax[0, 0], vals, xy, label="v", unit="N")
    arr = ax[0, 0].images[0].get_array()
    np.testing.assert_array_equal(np.asarray(arr), vals.reshape(2, 3))
    truth = np.zeros((4, 6))
    pred = truth + np.array([0, 0, 0, 0, 0, 2.0])
    plots.taxel_error_map(ax[0, 1], pred, truth, xy, unit="N", metric="max")
    assert np.asarray(ax[0, 1].images[0].get_array())[1, 2] == 2.0
    p = plots.save(fig, tmp_path / "m.png")
    assert p.stat().st_size > 3000
    with pytest.raises(ValueError, match="metric"):
        plots.taxel_error_map(ax[0, 1], pred, truth, xy, metric="median")


def test_creep_curve(tmp_path):
    from simulate.pictures import plots

    t = np.linspace(0, 20, 2001)
    v = np.where(t < 1, t, 1 + 0.05 * np.log1p(np.clip(t - 1, 0, None)))  # ramp then log creep
    fig, ax = plots.figure()
    plots.creep_curve(ax[0, 0], t, v, 1.0, label="strain")
    x, y = ax[0, 0].lines[0].get_data()
    assert x[0] > 0 and ax[0, 0].get_xscale() == "log"
    assert y[-1] == pytest.approx(100 * 0.05 * np.log1p(19.0), rel=1e-3)
    plots.save(fig, tmp_path / "c.png")
