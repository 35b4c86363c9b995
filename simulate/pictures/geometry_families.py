"""The fabric stack, the Velostat film between its ITO sheets and the 6 x 6 N-type elements, as pyvista meshes.

Registered in simulate.pictures.geometry.GEOMETRIES; interface in simulate.pictures.geometry.FamilyGeometry. Bodies are
unstructured grids of hexahedra built here point by point (explicit order: point data lines up with the
recording, whatever VTK's merge order). Thin stacks are drawn `z_stretch` times thicker than they are (a
0.6 mm stack on a 120 mm film is a line otherwise); the picture says so, and the export (display=False)
writes the true geometry.
"""

from __future__ import annotations

import numpy as np

from simulate.pictures.fields import EpisodeView, config_section
from simulate.pictures.geometry import FamilyGeometry, _padded_centres, _pv

STRETCHES = (1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 200.0, 500.0, 1000.0)
MIN_ASPECT = 0.06  # drawn thickness at least this fraction of the larger side
NAN_COLOR = "#d9d9d9"


def z_stretch_for(thickness_m: float, lateral_m: float, display: bool, min_aspect: float = MIN_ASPECT) -> float:
    """The smallest round factor that draws the stack at least min_aspect of its side thick (1 for export)."""
    if not display:
        return 1.0
    for f in STRETCHES:
        if thickness_m * f >= min_aspect * lateral_m:
            return f
    return STRETCHES[-1]


def _hexes(nx: int, ny: int, nz: int, offset: int = 0) -> np.ndarray:
    """(C, 8) VTK hexahedra of a block of nx x ny x nz nodes numbered x fastest, then y, then z."""
    i, j, k = np.meshgrid(np.arange(nx - 1), np.arange(ny - 1), np.arange(nz - 1), indexing="ij")
    i, j, k = i.ravel(), j.ravel(), k.ravel()

    def n(a, b, c):
        return offset + (c * ny + b) * nx + a

    return np.stack([n(i, j, k), n(i + 1, j, k), n(i + 1, j + 1, k), n(i, j + 1, k),
                     n(i, j, k + 1), n(i + 1, j, k + 1), n(i + 1, j + 1, k + 1), n(i, j + 1, k + 1)], axis=1)


def _ugrid(points: np.ndarray, hexes: np.ndarray):
    pv = _pv()
    return pv.UnstructuredGrid({pv.CellType.HEXAHEDRON: np.asarray(hexes, dtype=np.int64)},
                               np.asarray(points, dtype=np.float64))


class _TaxelSheet:
    """Nodes on the taxel centres plus the pad edges (like PadGeometry), for slabs of the taxel grid."""

    def __init__(self, lx: float, ly: float, nx: int, ny: int):
        self.lx, self.ly, self.nx, self.ny = lx, ly, nx, ny
        xs, ys = _padded_centres(lx, nx), _padded_centres(ly, ny)
        gy, gx = np.meshgrid(ys, xs, indexing="ij")
        self.xy = np.stack([gx.ravel(), gy.ravel()], axis=1)  # ((ny+2)(nx+2), 2), x fastest
        iy = np.clip(np.arange(ny + 2) - 1, 0, ny - 1)
        ix = np.clip(np.arange(nx + 2) - 1, 0, nx - 1)
        self.node_taxel = (iy[:, None] * nx + ix[None, :]).ravel()
        self.n = self.xy.shape[0]

    def slab(self, z_levels: list[np.ndarray], offset: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """Points and hexes of a slab whose node layers sit at z_levels[i] ((n,) each, bottom to top)."""
        pts = np.concatenate([np.column_stack([self.xy, z]) for z in z_levels])
        return pts, _hexes(self.nx + 2, self.ny + 2, len(z_levels), offset)

    def taxel_centres(self) -> np.ndarray:
        xs, ys = _padded_centres(self.lx, self.nx)[1:-1], _padded_centres(self.ly, self.ny)[1:-1]
        gx, gy = np.meshgrid(xs, ys)
        return np.stack([gx.ravel(), gy.ravel()], axis=1)


def read_channel(view: EpisodeView, channel: str) -> np.ndarray | None:
    """A recorded channel of the view's episode that the fields do not carry; None where absent."""
    from sensors.data.recording import Recording

    try:
        with Recording(view.path) as rec:
            if channel in rec.channels(view.ep_id):
                return np.asarray(rec.read(view.ep_id, channel), dtype=np.float64)
    except (OSError, KeyError, ValueError):  # a view not backed by a file: nothing extra to draw
        return None
    return None


def _pad(view: EpisodeView):
    pad = config_section(view, "pad")
    return (float(pad["size_x_m"]), float(pad["size_y_m"]), float(pad["thickness_m"]),
            int(pad["taxels_x"]), int(pad["taxels_y"]))


def _check_taxels(view: EpisodeView, nx: int, ny: int) -> None:
    if nx * ny != view.deformation_m.shape[1]:
        raise ValueError(f"pad.taxels_x x taxels_y = {nx * ny} but the recording has "
                         f"{view.deformation_m.shape[1]} taxels")


# ----------------------------------------------------------------------------------------------- fabric


class FabricStackGeometry(FamilyGeometry):
    """n knitted layers of thickness h / n on a silver-thread electrode, under a flat plate.

    Each layer is its own slab (drawn with a small gap so the layers read apart), nodes on the taxel grid;
    the compaction d of a taxel is shared equally by the layers (equal layers in series: uniform strain),
    so a point at height z moves down by d z / h. One readout channel: the stack's resistance is one value.
    """

    smooth = False

    def __init__(self, view: EpisodeView, display: bool = True):
        self.view = view
        self.lx, self.ly, self.h, nx, ny = _pad(view)
        _check_taxels(view, nx, ny)
        sensor = config_section(view, "sensor")
        self.layers = int(sensor.get("layers", view.sensor_attrs.get("layers", 1)))
        self.sheet = _TaxelSheet(self.lx, self.ly, nx, ny)
        # a 1 x 1 cm sample of 0.4-4.6 mm: drawn at least 3 mm thick so that the layers read apart
        self.z_stretch = z_stretch_for(self.h, max(self.lx, self.ly), display, min_aspect=0.3)
        self.top_z_m = self.h * self.z_stretch
        self.size_m = (self.lx, self.ly, self.top_z_m)
        t = self.h / self.layers
        gap = 0.06 * t if display else 0.0
        self._bounds = [(i * t + gap, (i + 1) * t - gap) for i in range(self.layers)]  # true z of each slab
        self.caption = f"{self.layers} layer{'s' if self.layers != 1 else ''} of {t * 1e3:.2f} mm" + (
            f", thickness drawn x{self.z_stretch:g}" if self.z_stretch != 1 else "")

    def body(self, deformation_m, point_fields, scale, index=None):
        d = np.asarray(deformation_m, dtype=np.float64)[self.sheet.node_taxel]
        pts, hexes, disp, layer = [], [], [], []
        for i, (z0, z1) in enumerate(self._bounds):
            levels = [self.z_stretch * z - scale * d * z / self.h for z in (z0, z1)]
            p, c = self.sheet.slab(levels, offset=i * 2 * self.sheet.n)
            pts.append(p)
            hexes.append(c)
            dz = np.concatenate([-d * z / self.h for z in (z0, z1)])
            disp.append(np.column_stack([np.zeros_like(dz), np.zeros_like(dz), dz]))
            layer.append(np.full(2 * self.sheet.n, i, dtype=np.int32))
        grid = _ugrid(np.concatenate(pts), np.concatenate(hexes))
        grid.point_data["displacement"] = np.concatenate(disp)
        grid.point_data["layer"] = np.concatenate(layer)
        node = np.tile(self.sheet.node_taxel, 2 * self.layers)
        for name, vals in point_fields.items():
            grid.point_data[name] = np.asarray(vals, dtype=np.float64)[node]
        return grid

    def static_parts(self):
        pv = _pv()
        t = 0.25 * self.h / self.layers * self.z_stretch
        m = 0.15 * max(self.lx, self.ly)
        base = pv.Box(bounds=(-self.lx / 2 - m, self.lx / 2 + m, -self.ly / 2 - m, self.ly / 2 + m, -t, 0.0))
        return [(base, dict(color="#b8bcc2", lighting=True))]

    def taxel_points(self) -> np.ndarray:
        return np.column_stack([self.sheet.taxel_centres(), np.full(self.sheet.nx * self.sheet.ny, self.top_z_m)])


# --------------------------------------------------------------------------------------------- velostat


class VelostatFilmGeometry(FamilyGeometry):
    """Three layers of equal thickness: the bottom PET-ITO sheet (busbars Y-/Y+ at y = -/+ L/2), the Velostat
    film (the body, coloured, nodes on the 10 mm cells) and the top PET-ITO sheet (busbars X-/X+ at
    x = -/+ L/2, drawn translucent so the film shows through). The stack compacts uniformly through its
    thickness (a point at height z moves down by d z / h). The ITO-decoded position of the sample, when
    recorded, is drawn as a red marker on the top sheet.
    """

    smooth = True
    SHEET_COLOR = "#9ec9e8"

    def __init__(self, view: EpisodeView, display: bool = True):
        self.view = view
        self.lx, self.ly, self.h, nx, ny = _pad(view)
        _check_taxels(view, nx, ny)
        self.sheet = _TaxelSheet(self.lx, self.ly, nx, ny)
        self.z_stretch = z_stretch_for(self.h, max(self.lx, self.ly), display)
        self.top_z_m = self.h * self.z_stretch
        self.size_m = (self.lx, self.ly, self.top_z_m)
        self.film_z = (self.h / 3, 2 * self.h / 3)
        self.decoded_xy = read_channel(view, "position_measured")
        self.caption = ("film between PET-ITO sheets (top one translucent)"
                        + (f", thickness x{self.z_stretch:g}" if self.z_stretch != 1 else "")
                        + ("\nred pin: ITO-decoded position" if self.decoded_xy is not None else ""))

    def _levels(self, d: np.ndarray, zs, scale: float):
        return [self.z_stretch * z - scale * d * z / self.h for z in zs]

    def body(self, deformation_m, point_fields, scale, index=None):
        d = np.asarray(deformation_m, dtype=np.float64)[self.sheet.node_taxel]
        pts, hexes = self.sheet.slab(self._levels(d, self.film_z, scale))
        grid = _ugrid(pts, hexes)
        dz = np.concatenate([-d * z / self.h for z in self.film_z])
        grid.point_data["displacement"] = np.column_stack([np.zeros_like(dz), np.zeros_like(dz), dz])
        node = np.tile(self.sheet.node_taxel, 2)
        for name, vals in point_fields.items():
            grid.point_data[name] = np.asarray(vals, dtype=np.float64)[node]
        return grid

    def _busbars(self, axis: int, z0: float, z1: float):
        pv = _pv()
        w = 0.02 * max(self.lx, self.ly)
        out = []
        for s in (-1, 1):
            if axis == 0:  # bars at x = -/+ lx/2 along y
                b = (s * self.lx / 2 - w / 2, s * self.lx / 2 + w / 2, -self.ly / 2, self.ly / 2, z0, z1)
            else:
                b = (-self.lx / 2, self.lx / 2, s * self.ly / 2 - w / 2, s * self.ly / 2 + w / 2, z0, z1)
            out.append((pv.Box(bounds=b), dict(color="#c8c8c8", lighting=True)))
        return out

    def static_parts(self):
        pv = _pv()
        zs = self.z_stretch
        bottom = pv.Box(bounds=(-self.lx / 2, self.lx / 2, -self.ly / 2, self.ly / 2, 0.0, zs * self.film_z[0]))
        parts = [(bottom, dict(color=self.SHEET_COLOR, lighting=True))]
        parts += self._busbars(1, 0.0, zs * self.film_z[0] * 1.05)  # Y-/Y+ on the bottom sheet
        parts += self._busbars(0, zs * self.film_z[1], self.top_z_m * 1.02)  # X-/X+ on the top sheet
        return parts

    def frame_parts(self, deformation_m, scale, index, field):
        pv = _pv()
        d = np.asarray(deformation_m, dtype=np.float64)[self.sheet.node_taxel]
        pts, hexes = self.sheet.slab(self._levels(d, (self.film_z[1], self.h), scale))
        top = _ugrid(pts, hexes)
        parts = [(top, dict(color=self.SHEET_COLOR, opacity=0.22, lighting=True, smooth_shading=True))]
        if self.decoded_xy is not None and index is not None:
            xy = self.decoded_xy[index]
            if np.all(np.isfinite(xy)):  # a red pin, standing clear of the (translucent) tip
                L = max(self.lx, self.ly)
                z1 = self.top_z_m + 0.2 * L
                stem = pv.Cylinder(center=(float(xy[0]), float(xy[1]), 0.5 * (self.top_z_m + z1)), direction=(0, 0, 1),
                                   radius=0.004 * L, height=z1 - self.top_z_m)
                head = pv.Sphere(radius=0.025 * L, center=(float(xy[0]), float(xy[1]), z1))
                parts.append((stem.merge(head), dict(color="red", lighting=True)))
        return parts

    def taxel_points(self) -> np.ndarray:
        n = self.sheet.nx * self.sheet.ny
        return np.column_stack([self.sheet.taxel_centres(), np.full(n, self.z_stretch * self.film_z[1])])


# ------------------------------------------------------------------------------------------------ ntype


class NtypeArrayGeometry(FamilyGeometry):
    """The 6 x 6 N-type elements with their three columns, under the array's top surface.

    Each column is a prism of the recorded cross-section from its bottom electrode along its direction n_j
    (attrs column_normals) for its length l_j (column_lengths_m); its top face follows the element's
    recorded top-electrode displacement (channel `displacement`, x scale). Columns of an element are laid
    side by side (inclined ones offset -/+ 0.2 pitch in x, the normal one at the centre). Column fields
    (strain, resistance: (T, 36 x 3), see fields_families.ntype_field) colour the columns, with the top
    surface translucent; taxel fields (pressure, deformation on the 24 x 24 load grid) colour the top
    surface, with the columns grey below.
    """

    smooth = False
    SKIN_M = 0.5e-3

    def __init__(self, view: EpisodeView, display: bool = True):
        self.view = view
        self.lx, self.ly, self.h, nx, ny = _pad(view)
        _check_taxels(view, nx, ny)
        a = view.sensor_attrs
        self.centres = np.asarray(a["element_xy_m"], dtype=np.float64)
        self.M = self.centres.shape[0]
        self.normals = np.asarray(a["column_normals"], dtype=np.float64)
        self.lengths = np.asarray(a["column_lengths_m"], dtype=np.float64)
        el = config_section(view, "sensor").get("element", {})
        self.side = float(np.sqrt(float(el.get("column_area_m2", 4e-6))))
        self.pitch = min(self.lx / int(a.get("elements_x", 6)), self.ly / int(a.get("elements_y", 6)))
        self.sheet = _TaxelSheet(self.lx, self.ly, nx, ny)
        self.n_taxels = nx * ny
        self.z_stretch = 1.0
        self.top_z_m = self.h
        self.size_m = (self.lx, self.ly, self.h)
        disp = read_channel(view, "displacement")
        self.disp = disp if disp is not None else np.zeros((view.n_samples, self.M, 3))
        # top of each column at rest (M, 3, 3): the element's top electrode plane
        vec = self.normals * self.lengths[:, None]  # (3, 3) bottom -> top
        off = np.zeros((3, 3))
        for j in range(3):
            lean = vec[j, :2]
            if np.linalg.norm(lean) > 1e-12:  # inclined: its top a quarter pitch from the element centre, along its lean
                off[j, :2] = 0.25 * self.pitch * lean / np.linalg.norm(lean) - lean / 2
        mid = off[None, :, :] + np.column_stack([self.centres, np.full(self.M, 0.0)])[:, None, :]
        self.bottom = mid - vec[None, :, :] / 2
        self.bottom[..., 2] = 0.0
        self.top = self.bottom + vec[None, :, :]
        count = int(config_section(view, "indenter").get("count", 1))
        self.caption = ("columns R_x, R_y (inclined), R_z (normal) per element"
                        + (f"\nindenter 1 of up to {count} drawn (only its position is recorded)" if count > 1 else ""))

    @property
    def peak_deflection_m(self) -> float:
        u = float(np.nanmax(np.linalg.norm(self.disp, axis=-1), initial=0.0))
        return max(u, float(np.nanmax(self.view.deformation_m, initial=0.0)))

    def is_column_field(self, values: np.ndarray) -> bool:
        return np.asarray(values).shape[-1] == 3 * self.M and 3 * self.M != self.n_taxels

    def _columns(self, index, scale):
        """Points (3M x 8, 3), hexes, true displacement per point."""
        u = self.disp[index] if index is not None else np.zeros((self.M, 3))
        s = self.side / 2
        sq = np.array([[-s, -s], [s, -s], [s, s], [-s, s]])
        pts, disp = [], []
        for m in range(self.M):
            for j in range(3):
                b, t = self.bottom[m, j], self.top[m, j]
                lo = np.column_stack([b[0] + sq[:, 0], b[1] + sq[:, 1], np.full(4, b[2])])
                hi = np.column_stack([t[0] + sq[:, 0], t[1] + sq[:, 1], np.full(4, t[2])]) + scale * u[m]
                pts += [lo, hi]
                disp += [np.zeros((4, 3)), np.tile(u[m], (4, 1))]
        P = np.concatenate(pts)
        hexes = np.arange(P.shape[0]).reshape(-1, 8)
        return P, hexes, np.concatenate(disp)

    def _skin(self, deformation_m, scale):
        d = np.asarray(deformation_m, dtype=np.float64)[self.sheet.node_taxel]
        zs = (self.h - self.SKIN_M, self.h)
        pts, hexes = self.sheet.slab([z - scale * d * z / self.h for z in zs])
        dz = np.concatenate([-d * z / self.h for z in zs])
        return pts, hexes, np.column_stack([np.zeros_like(dz), np.zeros_like(dz), dz])

    def body(self, deformation_m, point_fields, scale, index=None):
        col = {k: v for k, v in point_fields.items() if self.is_column_field(v)}
        tax = {k: v for k, v in point_fields.items() if k not in col}
        want_cols, want_skin = bool(col) or not tax, bool(tax) or not col
        pts, hexes, disp, where = [], [], [], []
        n0 = 0
        if want_skin:
            p, c, dsp = self._skin(deformation_m, scale)
            pts.append(p), hexes.append(c), disp.append(dsp), where.append(("skin", n0, len(p)))
            n0 += len(p)
        if want_cols:
            p, c, dsp = self._columns(index, scale)
            pts.append(p), hexes.append(c + n0), disp.append(dsp), where.append(("cols", n0, len(p)))
        grid = _ugrid(np.concatenate(pts), np.concatenate(hexes))
        grid.point_data["displacement"] = np.concatenate(disp)
        skin_node = np.tile(self.sheet.node_taxel, 2)
        col_node = np.repeat(np.arange(3 * self.M), 8)  # point -> flat column index 3 m + j
        for name, vals in point_fields.items():
            vals = np.asarray(vals, dtype=np.float64)
            arr = np.full(grid.n_points, np.nan)
            for part, a, n in where:
                if part == "skin" and name in tax:
                    arr[a:a + n] = vals[skin_node]
                elif part == "cols" and name in col:
                    arr[a:a + n] = vals[col_node]
            grid.point_data[name] = arr
        if want_cols:
            part = np.full(grid.n_points, -1, dtype=np.int32)
            a, n = where[-1][1], where[-1][2]
            part[a:a + n] = np.repeat(np.arange(3 * self.M) % 3, 8)
            grid.point_data["column"] = part  # 0 R_x, 1 R_y, 2 R_z; -1 top surface
        return grid

    def static_parts(self):
        pv = _pv()
        t = 0.06 * self.h
        base = pv.Box(bounds=(-self.lx / 2, self.lx / 2, -self.ly / 2, self.ly / 2, -t, 0.0))
        e = 0.5 * self.pitch
        pads = [pv.Box(bounds=(c[0] - e * 0.9, c[0] + e * 0.9, c[1] - e * 0.6, c[1] + e * 0.6, 0.0, 0.02 * self.h))
                for c in self.centres]
        return [(base, dict(color="#5b6169", lighting=True)),
                (pv.merge(pads), dict(color="#c8a24a", lighting=True))]  # bottom electrodes

    def frame_parts(self, deformation_m, scale, index, field):
        values = self.view.fields.get(field)
        column_field = values is not None and self.is_column_field(values)
        if column_field:
            p, c, _ = self._skin(deformation_m, scale)
            return [(_ugrid(p, c), dict(color="#d0d4d8", opacity=0.12, lighting=True))]
        p, c, _ = self._columns(index, scale)
        return [(_ugrid(p, c), dict(color="#8a9099", lighting=True))]

    def taxel_points(self) -> np.ndarray:
        return np.column_stack([self.sheet.taxel_centres(), np.full(self.n_taxels, self.h)])

    def column_points(self, index: int | None = None, scale: float = 0.0) -> np.ndarray:
        """(3M, 3) centre of each column's top face (flat index 3 m + j), displaced by scale x the recording."""
        u = self.disp[index] if index is not None else np.zeros((self.M, 3))
        return (self.top + scale * u[:, None, :]).reshape(-1, 3)
