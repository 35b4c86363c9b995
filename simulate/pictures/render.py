"""3-D pictures and animations of a recorded episode with pyvista (the optional `viz` extra, imported lazily).

`render_frame` draws the sensing body of the family (simulate.pictures.geometry) displaced by the recorded
deformation times a stated exaggeration factor, coloured by one field with a labelled scalar bar in
real units, and the indenter where it was. With no display (no DISPLAY / WAYLAND_DISPLAY on Linux) it
renders offscreen through EGL; with a display `show_window` opens an interactive window.
`render_animation` writes an .mp4 or .gif over an episode with time and force in every frame.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from simulate.pictures.fields import FIELDS, EpisodeView, FieldError, nice_exaggeration
from simulate.pictures.geometry import FamilyGeometry, indenter_mesh, make_geometry
from simulate.pictures.pyvista_setup import VizUnavailable, has_display, import_pyvista  # noqa: F401  (has_display: public here)

BACKGROUND = "white"
NAN_COLOR = "#d9d9d9"  # where a field has no value (velostat resistance off the contact, N-type columns vs skin)


@dataclass
class FrameInfo:
    """What a rendered frame shows (for captions and tests)."""

    field: str
    index: int
    time_s: float
    force_n: float
    clim: tuple[float, float]  # scalar bar range, display units
    unit: str
    exaggeration: float
    indenter_px: tuple[int, int] | None  # (row, col) of the pad surface under the indenter's centre


@dataclass
class RenderOptions:
    """Look of a frame. `view`: 'iso' (3/4 view from the front) or 'top' (straight down, parallel projection)."""

    window_size: tuple[int, int] = (896, 640)
    view: str = "iso"
    exaggeration: float | None = None  # None: a round factor that shows the episode's peak at ~30 % of thickness
    clim: tuple[float, float] | None = None  # display units; None: the frame's range (animations: the episode's)
    show_indenter: bool = True
    lighting: bool = True
    show_text: bool = True
    show_parts: bool = True  # the family's uncoloured parts (sheets, electrodes, base); off for pixel probes


class Scene:
    """A plotter with the body, static parts, the indenter and texts; frames update it in place."""

    def __init__(self, view: EpisodeView, field: str, opts: RenderOptions, off_screen: bool):
        if field not in FIELDS:
            raise FieldError(f"unknown field '{field}' (allowed: {', '.join(FIELDS)})")
        if field not in view.fields:
            raise FieldError(f"episode {view.ep_id} has no '{field}' field")
        self.pv = import_pyvista()
        self.view, self.field, self.opts = view, field, opts
        self.spec = FIELDS[field]
        self.geom: FamilyGeometry = make_geometry(view)
        h = self.geom.top_z_m
        self.scale = opts.exaggeration or nice_exaggeration(self.geom.peak_deflection_m, h)
        try:
            self.pl = self.pv.Plotter(off_screen=off_screen, window_size=list(opts.window_size))
        except Exception as exc:  # pragma: no cover - no OpenGL at all
            raise VizUnavailable(f"cannot open an OpenGL context for rendering ({exc})") from None
        self.pl.set_background(BACKGROUND)
        self._body_actor = None
        self._ind_actor = None
        self._part_actors: list = []
        self._texts: list = []
        self._bar = False
        self._camera_set = False
        if opts.show_parts:
            for mesh, kw in self.geom.static_parts():
                self.pl.add_mesh(mesh, **_lit(kw, opts.lighting))

    def values(self, k: int) -> np.ndarray:
        return self.view.fields[self.field][k] * self.spec.scale

    def episode_clim(self) -> tuple[float, float]:
        v = self.view.fields[self.field] * self.spec.scale
        return _clim(*_nanrange(v))

    def _font(self, base: int) -> int:
        return max(6, int(round(base * self.opts.window_size[1] / 640)))

    def frame_clim(self, k: int) -> tuple[float, float]:
        """The colour range of sample k: the frame's own range; the episode's where the frame is uniform
        (a single readout channel colours the whole pad alike)."""
        vals = self.values(k)
        lo, hi = _nanrange(vals)
        if not hi - lo > 1e-9 * max(abs(hi), abs(lo), 1e-30):
            return self.episode_clim()
        return _clim(lo, hi)

    def draw(self, k: int, clim: tuple[float, float] | None = None) -> FrameInfo:
        pl, opts, view = self.pl, self.opts, self.view
        vals = self.values(k)
        clim = clim or opts.clim or self.frame_clim(k)
        body = self.geom.body(view.deformation_m[k], {self.field: vals}, self.scale, index=k)
        if self._body_actor is not None:
            pl.remove_actor(self._body_actor, render=False)
        self._body_actor = pl.add_mesh(
            body, scalars=self.field, cmap=self.spec.cmap, clim=list(clim), lighting=opts.lighting,
            smooth_shading=opts.lighting and self.geom.smooth, show_scalar_bar=False, nan_color=NAN_COLOR,
        )
        for a in self._part_actors:
            pl.remove_actor(a, render=False)
        self._part_actors = []
        if opts.show_parts:
            for mesh, kw in self.geom.frame_parts(view.deformation_m[k], self.scale, k, self.field):
                self._part_actors.append(pl.add_mesh(mesh, **_lit(kw, opts.lighting)))
        if not self._bar:
            w, hgt = opts.window_size
            pl.add_scalar_bar(
                title=" ", color="black", vertical=True, position_x=0.86, position_y=0.1, width=0.07,
                height=0.66, label_font_size=self._font(15), fmt="%.3g", n_labels=5, mapper=self._body_actor.mapper,
            )
            label = pl.add_text(f"{self.spec.label}\n({self.spec.unit})", position=(0.99 * w, 0.80 * hgt),
                                font_size=self._font(11), color="black")
            label.GetTextProperty().SetJustificationToRight()
            self._bar = True
        self._body_actor.mapper.scalar_range = clim
        if self._ind_actor is not None:
            pl.remove_actor(self._ind_actor, render=False)
            self._ind_actor = None
        if opts.show_indenter:
            ind = indenter_mesh(view, k, self.geom.top_z_m, self.scale, self.geom.real_top_z_m)
            if ind is not None:
                self._ind_actor = pl.add_mesh(ind, color="#9aa4ad", opacity=0.35, lighting=opts.lighting)
        for a in self._texts:
            pl.remove_actor(a, render=False)
        self._texts = []
        t, f = float(view.time_s[k]), float(view.force_n[k])
        if opts.show_text:
            w, hgt = opts.window_size
            fs = self._font(11)
            top = pl.add_text(  # pixel-placed text actors: corner annotations shrink away in small frames
                f"t = {t:.2f} s   F = {f:.2f} N\n{view.family} · {view.ep_id}",
                position=(0.01 * w, hgt - 4), font_size=fs, color="black")
            top.GetTextProperty().SetVerticalJustificationToTop()
            self._texts.append(top)
            foot = f"deformation shown x{self.scale:g}"
            if self.geom.caption:
                foot += "; " + self.geom.caption
            if self.field in view.notes:
                foot += "\n" + view.notes[self.field]
            self._texts.append(pl.add_text(foot, position=(0.01 * w, 4), font_size=self._font(9), color="black"))
        if not self._camera_set:
            self._set_camera()
            self._camera_set = True
        return FrameInfo(self.field, k, t, f, (float(clim[0]), float(clim[1])), self.spec.unit, self.scale,
                         self._indenter_pixel(k))

    def _set_camera(self) -> None:
        lx, ly, h = self.geom.size_m
        pl = self.pl
        c = (0.0, 0.0, 0.5 * h)
        if self.opts.view == "top":
            pl.enable_parallel_projection()
            L = max(lx, ly)
            c = (0.12 * L, 0.0, 0.5 * h)  # pad left of the scalar bar, clear of the captions
            pl.camera_position = [(c[0], 0.0, 10 * L), c, (0.0, 1.0, 0.0)]
            pl.reset_camera_clipping_range()
            pl.camera.parallel_scale = 0.66 * L
        else:
            d = 1.9 * max(lx, ly, h)
            pl.camera_position = [(0.55 * d, -1.0 * d, 0.85 * d), c, (0.0, 0.0, 1.0)]
            pl.reset_camera()
            pl.camera.zoom(1.15)
            # shift the view right (the pad moves left, clear of the scalar bar)
            f, p = np.array(pl.camera.focal_point), np.array(pl.camera.position)
            right = np.cross(f - p, np.array(pl.camera.up))
            up = np.cross(right, f - p)
            shift = max(lx, ly) * (0.12 * right / np.linalg.norm(right) - 0.07 * up / np.linalg.norm(up))
            pl.camera.focal_point, pl.camera.position = tuple(f + shift), tuple(p + shift)

    def _indenter_pixel(self, k: int) -> tuple[int, int] | None:
        p = self.view.position_m[k]
        if not np.all(np.isfinite(p)):
            return None
        return self.world_to_pixel((p[0], p[1], self.geom.top_z_m))

    def world_to_pixel(self, xyz) -> tuple[int, int]:
        """(row, col) in the image of a point in drawn world coordinates (after draw)."""
        from vtkmodules.vtkRenderingCore import vtkCoordinate

        coord = vtkCoordinate()
        coord.SetCoordinateSystemToWorld()
        coord.SetValue(float(xyz[0]), float(xyz[1]), float(xyz[2]))
        x, y = coord.GetComputedDisplayValue(self.pl.renderer)
        w, hgt = self.pl.window_size
        return (int(hgt - 1 - y), int(x))

    def image(self) -> np.ndarray:
        return np.asarray(self.pl.screenshot(return_img=True))

    def close(self) -> None:
        self.pl.close()


def _lit(kw: dict, lighting: bool) -> dict:
    """add_mesh kwargs of a part, unlit (flat colours) where the frame is drawn without lighting."""
    kw = dict(kw)
    if not lighting:
        kw["lighting"] = False
        kw.pop("smooth_shading", None)
    return kw


def _nanrange(v: np.ndarray) -> tuple[float, float]:
    """(min, max) over the finite values; (nan, nan) where there are none (no touch)."""
    v = np.asarray(v, dtype=np.float64)
    f = v[np.isfinite(v)]
    return (float(f.min()), float(f.max())) if f.size else (float("nan"), float("nan"))


def _clim(lo: float, hi: float) -> tuple[float, float]:
    if not np.isfinite(lo) or not np.isfinite(hi):
        return (0.0, 1.0)
    if 0.0 <= lo < 1e-6 * hi:  # rounding noise above an unloaded zero: start the bar at 0
        lo = 0.0
    if hi - lo < 1e-12 * max(1.0, abs(hi)):  # a uniform field still gets a readable bar
        pad = 0.01 * abs(hi) if hi != 0 else 1e-9
        return (lo - pad, hi + pad)
    return (lo, hi)


def render_frame(
    view: EpisodeView, field: str, index: int, out: str | Path | None = None, opts: RenderOptions | None = None
) -> tuple[np.ndarray, FrameInfo]:
    """Render sample `index` offscreen; returns the RGB image (H, W, 3) and what it shows; writes a PNG to `out`."""
    opts = opts or RenderOptions()
    sc = Scene(view, field, opts, off_screen=True)
    try:
        info = sc.draw(index)
        img = sc.image()
    finally:
        sc.close()
    if out is not None:
        write_png(img, out)
    return img, info


def show_window(view: EpisodeView, field: str, index: int, opts: RenderOptions | None = None) -> FrameInfo:
    """Open an interactive window (needs a display)."""
    sc = Scene(view, field, opts or RenderOptions(), off_screen=False)
    info = sc.draw(index)
    sc.pl.show()
    return info


def write_png(img: np.ndarray, out: str | Path) -> Path:
    import matplotlib.image

    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    matplotlib.image.imsave(out, np.ascontiguousarray(img[..., :3]))
    return out


def frame_indices(view: EpisodeView, fps: float, stride: int | None = None, max_frames: int | None = None) -> np.ndarray:
    """Samples to animate: every `stride`-th (default: real-time playback at `fps`), at most `max_frames`."""
    n = view.n_samples
    if stride is None:
        dt = float(np.median(np.diff(view.time_s))) if n > 1 else 1.0
        stride = max(1, int(round(1.0 / (fps * dt))))
    if max_frames is not None and max_frames < 1:
        raise ValueError(f"max_frames must be >= 1 (got {max_frames}; None for every frame)")
    idx = np.arange(0, n, stride)
    if max_frames is not None and len(idx) > max_frames:
        idx = idx[np.linspace(0, len(idx) - 1, max_frames).round().astype(int)]
    return idx


def render_animation(
    view: EpisodeView,
    field: str,
    out: str | Path,
    *,
    fps: float = 25.0,
    stride: int | None = None,
    max_frames: int | None = None,
    opts: RenderOptions | None = None,
    on_frame: Callable[[int, int], None] | None = None,
) -> tuple[Path, FrameInfo]:
    """Write an .mp4 or .gif of the episode; the colour range is the episode's (comparable across frames).

    on_frame(done, total) after each frame (progress bars). Returns the path and the last frame's info.
    """
    out = Path(out)
    ext = out.suffix.lower()
    if ext not in (".mp4", ".gif"):
        raise FieldError(f"animation file '{out}' must end in .mp4 or .gif")
    try:
        import imageio.v2 as imageio
    except ImportError:  # pragma: no cover
        raise VizUnavailable("animations need imageio and imageio-ffmpeg: pip install 'piezotwin[viz]'") from None
    opts = opts or RenderOptions()
    idx = frame_indices(view, fps, stride, max_frames)
    out.parent.mkdir(parents=True, exist_ok=True)
    sc = Scene(view, field, opts, off_screen=True)
    clim = opts.clim or sc.episode_clim()
    if ext == ".gif":
        writer = imageio.get_writer(out, mode="I", duration=1000.0 / fps, loop=0)  # ms per frame
    else:
        writer = imageio.get_writer(out, fps=fps, codec="libx264", quality=7, macro_block_size=16,
                                    ffmpeg_log_level="error")
    info = None
    try:
        for j, k in enumerate(idx):
            info = sc.draw(int(k), clim)
            writer.append_data(sc.image())
            if on_frame:
                on_frame(j + 1, len(idx))
    finally:
        writer.close()
        sc.close()
    return out, info
