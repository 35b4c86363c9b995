"""Pictures of the fabric stack, the Velostat film and the N-type array, their ParaView export, and the
velostat plots (dendrogram, position error maps): render offscreen and check what the picture shows.

One tiny recording per family (numpy backend, < 2 s together): fabric_3 under a 4 N hold, a Velostat
1-3 N staircase, one N-type press-and-stroke with a single indenter. Rendering tests skip with the
reason where there is no pyvista or offscreen OpenGL.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from typer.testing import CliRunner

from scenes import load_scene
from sensors.data.recording import Recording

SMALL = (240, 176)
SPECS = {
    "fabric": ("fabric_3", ["protocol.kind=hold", "protocol.ramp_s=1", "protocol.duration_s=3",
                            "protocol.amplitude_min=4", "protocol.amplitude_max=4"]),
    "velostat": ("velostat", ["protocol.kind=velostat_staircase", "protocol.staircase_max_n=3",
                              "protocol.step_hold_s=2", "protocol.duration_s=12"]),
    "ntype": ("ntype", ["indenter.count=1"]),
}


@pytest.fixture(scope="module")
def recs(tmp_path_factory):
    from simulate.generation.run import generate

    d = tmp_path_factory.mktemp("vizfam")
    out = {}
    for fam, (preset, ov) in SPECS.items():
        cfg = load_scene(preset, ov + ["generation.episodes=1", "generation.episodes_per_shard=1",
                                       "generation.root_seed=3"])
        generate(cfg, d / fam, backend="numpy")
        out[fam] = d / fam / "shard-00000.h5"
    return out


def _decode(img, cmap, clim, tol=12.0):
    import matplotlib

    lut = (matplotlib.colormaps[cmap](np.linspace(0, 1, 256))[:, :3] * 255.0)
    px = img[..., :3].reshape(-1, 3).astype(np.float64)
    d2 = ((px[:, None, :] - lut[None, :, :]) ** 2).sum(-1)
    j = d2.argmin(1)
    vals = clim[0] + (clim[1] - clim[0]) * j / 255.0
    vals[np.sqrt(d2[np.arange(len(j)), j]) > tol] = np.nan
    return vals.reshape(img.shape[:2])


def _is_picture(img):
    background = np.all(img > 245, axis=-1)
    assert 0.1 < 1 - background.mean() < 0.97
    assert len(np.unique(img.reshape(-1, 3), axis=0)) > 100


def _probe(render, view, field, k, points=()):
    """Top view, flat colours, nothing but the coloured body: (image, info, pixels of `points`); each point
    (x, y, z) or a function of the exaggeration giving one."""
    opts = render.RenderOptions(window_size=SMALL, view="top", lighting=False, show_text=False,
                                show_indenter=False, show_parts=False)
    sc = render.Scene(view, field, opts, off_screen=True)
    try:
        info = sc.draw(k)
        img = sc.image()
        px = [sc.world_to_pixel(p(info.exaggeration) if callable(p) else p) for p in points]
        return img, info, px
    finally:
        sc.close()


# ----------------------------------------------------------------------------- fields (numbers)


def test_field_mappers_follow_the_recordings(views, recs):
    nt, fa, ve = views["ntype"], views["fabric"], views["velostat"]
    with Recording(recs["ntype"]) as rec:
        r = rec.read(nt.ep_id, "resistance")
        s = rec.read(nt.ep_id, "strain")
    assert nt.fields["resistance"].shape == (nt.n_samples, 108) and nt.fields["pressure"].shape[1] == 576
    np.testing.assert_allclose(nt.fields["resistance"][:, 3 * 14 + 2], r[:, 14, 2])  # element 14, R_z
    np.testing.assert_allclose(nt.fields["strain"], -s.reshape(nt.n_samples, -1))  # compression positive
    assert "compression positive" in nt.notes["strain"]
    with Recording(recs["fabric"]) as rec:
        np.testing.assert_allclose(fa.fields["resistance"][:, 0], rec.read(fa.ep_id, "resistance")[:, 0])
    assert "3-layer stack" in fa.notes["resistance"]
    with Recording(recs["velostat"]) as rec:
        rv = rec.read(ve.ep_id, "resistance")
    loaded = ve.fields["pressure"] > 0
    assert np.isnan(ve.fields["resistance"][~loaded]).all()
    k = ve.peak_index()
    np.testing.assert_allclose(ve.fields["resistance"][k][loaded[k]], rv[k])
    assert np.isnan(ve.fields["resistance"][0]).all()  # no touch: open circuit, nothing shown


def test_fabric_more_layers_more_slabs(offscreen, views):
    from simulate.pictures.geometry import make_geometry

    v = views["fabric"]
    k = v.peak_index()
    d = float(v.deformation_m[k, 0])
    for n in (1, 3, 6, 12):
        cfg = dict(v.config, sensor=dict(v.config["sensor"], layers=n))
        g = make_geometry(dataclasses.replace(v, config=cfg))
        body = g.body(v.deformation_m[k], {"pressure": v.fields["pressure"][k]}, 10.0)
        assert body.connectivity("all")["RegionId"].max() + 1 == n
        assert sorted(np.unique(body.point_data["layer"])) == list(range(n))
        # the top of the stack is pressed down by the exaggerated compaction, the bottom stays
        assert body.bounds[5] == pytest.approx((g.top_z_m - 10.0 * d) * (1 - 0.06 / n), rel=1e-6)
        assert body.bounds[4] >= 0.0
        assert np.allclose(body.point_data["pressure"], v.fields["pressure"][k, 0])
    assert make_geometry(v, display=False).top_z_m == pytest.approx(1.14e-3)  # export: true thickness


# ----------------------------------------------------------------------------- pictures


def test_fabric_picture(offscreen, views, tmp_path):
    v = views["fabric"]
    img, info = offscreen.render_frame(v, "deformation", v.peak_index(), tmp_path / "f.png",
                                       offscreen.RenderOptions(window_size=SMALL))
    _is_picture(img)
    assert info.clim[1] == pytest.approx(v.deformation_m.max() * 1e6, rel=1e-6)
    assert info.exaggeration >= 2
    # resistance: one channel, the whole stack one colour; the bar spans the episode's range
    img_r, info_r = offscreen.render_frame(v, "resistance", v.peak_index(), None,
                                           offscreen.RenderOptions(window_size=SMALL))
    assert info_r.clim[0] < v.fields["resistance"][v.peak_index(), 0] < info_r.clim[1]
    _is_picture(img_r)


def test_velostat_hot_spot_is_where_the_tip_was(offscreen, views):
    v = views["velostat"]
    k = v.peak_index()
    far_xy = (-v.position_m[k, 0], -v.position_m[k, 1], 0.0)
    img, info, (p0, p1, far) = _probe(offscreen, v, "pressure", k, [(0.0, 0.0, 0.0), (0.01, 0.0, 0.0), far_xy])
    vals = _decode(img[:, : int(0.8 * SMALL[0])], "plasma", info.clim)
    assert np.isfinite(vals).mean() > 0.3
    r, c = np.unravel_index(np.nanargmax(vals), vals.shape)
    assert np.nanmax(vals) > 0.9 * info.clim[1]
    ir, ic = info.indenter_px
    pitch_px = abs(p1[1] - p0[1])  # one 10 mm cell
    assert abs(r - ir) <= 1.5 * pitch_px and abs(c - ic) <= 1.5 * pitch_px, (r, c, info.indenter_px)
    # far from the tip the film is at rest
    assert vals[far] < 0.05 * info.clim[1]


def test_velostat_picture_has_sheets_tip_and_decoded_position(offscreen, views):
    v = views["velostat"]
    k = v.peak_index()
    img, info = offscreen.render_frame(v, "pressure", k, None, offscreen.RenderOptions(window_size=(320, 224)))
    _is_picture(img)
    red = (img[..., 0] > 190) & (img[..., 1] < 70) & (img[..., 2] < 70)
    assert red.sum() > 3  # the ITO-decoded position marker
    rows, cols = np.nonzero(red)
    ir, ic = info.indenter_px
    assert abs(rows.mean() - ir) < 0.2 * 224 and abs(cols.mean() - ic) < 0.2 * 320
    assert info.exaggeration > 10  # micrometres of compaction on a film drawn 20x thicker


def test_ntype_pressed_element_normal_column_is_the_extreme(offscreen, views):
    from simulate.pictures.geometry import make_geometry

    v = views["ntype"]
    with Recording(v.path) as rec:
        fz = rec.read(v.ep_id, "force_element")[..., 2]
    k = int(np.argmax(fz.max(axis=1)))
    m = int(np.argmax(fz[k]))
    res = v.fields["resistance"][k]
    assert int(np.argmin(res)) == 3 * m + 2  # numbers: the pressed element's R_z is the lowest
    g = make_geometry(v)
    body = g.body(v.deformation_m[k], {"resistance": res}, 2.0, index=k)
    pts = body.point_data["resistance"]
    lowest = body.points[np.nanargmin(pts)]
    assert np.linalg.norm(lowest[:2] - g.column_points(k, 2.0)[3 * m + 2, :2]) < 2e-3
    assert np.isnan(pts).sum() == 0  # a column field: the body is the columns only
    # picture: the darkest blue of the map sits on that column
    img, info, (cpx,) = _probe(offscreen, v, "resistance", k, [lambda s: g.column_points(k, s)[3 * m + 2]])
    assert info.clim == pytest.approx((res.min(), res.max()), rel=1e-6)
    vals = _decode(img[:, : int(0.8 * SMALL[0])], "coolwarm", info.clim, tol=10.0)
    r, c = np.unravel_index(np.nanargmin(vals), vals.shape)
    cr, cc = cpx
    assert abs(r - cr) <= 4 and abs(c - cc) <= 4, ((r, c), (cr, cc))
    assert np.nanmin(vals) < res.min() + 0.03 * np.ptp(res)
    # and with all parts (translucent top surface, electrodes, base) it is a picture
    img2, _ = offscreen.render_frame(v, "resistance", k, None, offscreen.RenderOptions(window_size=SMALL))
    _is_picture(img2)


def test_ntype_pressure_colours_the_top_surface(offscreen, views):
    v = views["ntype"]
    k = v.peak_index()
    img, info, _ = _probe(offscreen, v, "pressure", k)
    vals = _decode(img[:, : int(0.8 * SMALL[0])], "plasma", info.clim)
    r, c = np.unravel_index(np.nanargmax(vals), vals.shape)
    ir, ic = info.indenter_px
    assert abs(r - ir) < 0.1 * SMALL[1] and abs(c - ic) < 0.1 * SMALL[1]


def test_animation_velostat(offscreen, views, tmp_path):
    import imageio.v3 as iio

    v = views["velostat"]
    out, info = offscreen.render_animation(v, "pressure", tmp_path / "a.gif", fps=10, max_frames=4,
                                           opts=offscreen.RenderOptions(window_size=(160, 112)))
    frames = iio.imread(out, index=None)
    assert frames.shape[0] == 4
    assert np.abs(frames[0].astype(int) - frames[2].astype(int)).mean() > 0.5


# ----------------------------------------------------------------------------- export and command line


def test_export_round_trip_ntype(offscreen, views, tmp_path):
    import pyvista as pv

    from simulate.pictures.export import export_episode
    from simulate.pictures.geometry import make_geometry

    v = views["ntype"]
    pvd = export_episode(v, tmp_path / "vtk", stride=4)
    reader = pv.get_reader(str(pvd))
    np.testing.assert_allclose(reader.time_values, v.time_s[::4], atol=1e-12)
    k = 8
    reader.set_active_time_value(float(v.time_s[k]))
    body = reader.read()[0]
    g = make_geometry(v, display=False)
    # columns: each column's top face carries its recorded resistance; the top surface has NaN there
    cols = body.point_data["column"] >= 0
    top = g.column_points(k, 0.0)
    ids = [int(np.flatnonzero(cols)[np.argmin(np.linalg.norm(body.points[cols] - p, axis=1))]) for p in top]
    np.testing.assert_allclose(body.point_data["resistance"][ids], v.fields["resistance"][k], rtol=1e-6)
    assert np.isnan(body.point_data["resistance"][~cols]).all()
    assert np.isnan(body.point_data["pressure"][cols]).all()
    # the top surface carries the load field at the taxel centres
    skin = np.flatnonzero(~cols)
    tp = g.taxel_points()
    sid = [int(skin[np.argmin(np.linalg.norm(body.points[skin] - p, axis=1))]) for p in tp]
    np.testing.assert_allclose(body.points[sid], tp, atol=1e-9)
    np.testing.assert_allclose(body.point_data["pressure"][sid], v.fields["pressure"][k], rtol=1e-6)
    # the columns' top faces moved by the recorded electrode displacement (true scale)
    with Recording(v.path) as rec:
        u = rec.read(v.ep_id, "displacement")[k]
    np.testing.assert_allclose(body.point_data["displacement"][ids], np.repeat(u, 3, axis=0), rtol=1e-5, atol=1e-12)


def test_cli_show_and_export_each_family(offscreen, recs, tmp_path):
    from piezotwin.cli import app

    runner = CliRunner()
    for fam, field in (("fabric", "resistance"), ("velostat", "deformation"), ("ntype", "strain")):
        out = tmp_path / f"{fam}.png"
        res = runner.invoke(app, ["show", str(recs[fam]), "-f", field, "-o", str(out), "--size", "200x140"])
        assert res.exit_code == 0, res.output
        assert out.stat().st_size > 1000
    res = runner.invoke(app, ["export", str(recs["velostat"]), "-o", str(tmp_path / "vtk"), "--stride", "40"])
    assert res.exit_code == 0, res.output
    import pyvista as pv

    body = pv.get_reader(str(tmp_path / "vtk" / "ep-000000.pvd")).read()[0]
    assert body.bounds[5] == pytest.approx(0.4e-3, rel=1e-6)  # the film's top at true scale (2/3 of 0.6 mm)
    res = runner.invoke(app, ["show", str(recs["ntype"]), "-f", "force_taxel"])
    assert res.exit_code == 2 and "no 'force_taxel' channel" in res.output


# ----------------------------------------------------------------------------- plots


def test_unit_dendrogram_has_36_leaves(tmp_path):
    from simulate.pictures import plots

    rng = np.random.default_rng(0)
    F = np.arange(1.0, 16.0)
    base = 2e4 / F
    scale = np.repeat([0.6, 1.0, 1.6], 12)  # three groups of 12 units
    R = base[None, :] * scale[:, None] * (1 + 0.02 * rng.standard_normal((36, 15)))
    fig, ax = plots.figure(size=(8, 3.5))
    _, Z, leaves = plots.unit_dendrogram(ax[0, 0], R, n_groups=3, title="units")
    assert sorted(leaves) == list(range(36))
    labels = [t.get_text() for t in ax[0, 0].get_xticklabels()]
    assert len(labels) == 36 and set(labels) == {str(i) for i in range(1, 37)}
    # the cut leaves the three groups: the leaves of each group are contiguous and the line sits between merges
    from scipy.cluster.hierarchy import fcluster

    g = fcluster(Z, 3, criterion="maxclust")
    assert len(set(g[:12])) == len(set(g[12:24])) == len(set(g[24:])) == 1 and len(set(g)) == 3
    cut = [ln for ln in ax[0, 0].lines if ln.get_linestyle() == "--"]
    assert cut and np.sort(Z[:, 2])[-3] < cut[0].get_ydata()[0] < np.sort(Z[:, 2])[-2]
    colours = {tuple(np.round(c.get_edgecolor()[0], 3)) for c in ax[0, 0].collections}
    assert len(colours) >= 3
    p = plots.save(fig, tmp_path / "d.png")
    assert p.stat().st_size > 5000
    with pytest.raises(ValueError, match="units >= 2"):
        plots.unit_dendrogram(ax[0, 0], R[:1])


def test_position_error_maps(tmp_path):
    from simulate.pictures import plots

    c = (np.arange(6) - 2.5) * 0.02
    gx, gy = np.meshgrid(c, c)
    truth = np.stack([gx.ravel(), gy.ravel()], axis=1)  # the 36 unit centres, x fastest
    dec = np.stack([truth + 0.5e-3, truth.copy()])  # 0.5 mm off everywhere at 1 N, exact at 15 N ...
    dec[1, 7] += (3e-3, 0.0)  # ... but unit 8 reads 3 mm to the right
    dec[0, 0] = np.nan  # no reading
    fig, ax = plots.figure(1, 2, size=(9, 4))
    _, err = plots.position_error_maps(ax[0], truth, dec, [1.0, 15.0], size_m=(0.12, 0.12), label="4-wire")
    np.testing.assert_allclose(err[0, 1:], np.hypot(0.5, 0.5))
    assert err[1, 7] == pytest.approx(3.0) and np.isnan(err[0, 0])
    img1 = np.asarray(ax[0, 1].images[0].get_array())
    assert img1[1, 1] == pytest.approx(3.0) and img1[0, 0] == 0.0  # unit 8 = row 1, column 1
    assert ax[0, 0].images[0].get_clim() == ax[0, 1].images[0].get_clim() == (0.0, pytest.approx(3.0))
    assert "15 N" in ax[0, 1].get_title() and "4-wire" in ax[0, 0].get_title()
    q = ax[0, 1].collections[-1]  # the arrows
    assert np.asarray(q.U)[7] == pytest.approx(15.0)  # 3 mm x 5
    p = plots.save(fig, tmp_path / "pe.png")
    assert p.stat().st_size > 5000
    # scattered sites (not a grid) work too
    fig, ax = plots.figure()
    _, e = plots.position_error_map(ax[0, 0], truth[[0, 8, 20]], truth[[0, 8, 20]] + 1e-3, size_m=(0.12, 0.12))
    np.testing.assert_allclose(e, np.hypot(1, 1))
    plots.save(fig, tmp_path / "ps.png")
