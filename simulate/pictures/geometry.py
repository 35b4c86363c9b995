"""Each sensor family in its real geometry, as pyvista meshes (imported lazily: pyvista is the `viz` extra).

A family adds one line to `GEOMETRIES` (family -> "module:Class") and a class with the `FamilyGeometry`
interface below; `simulate.pictures.render` (pictures, animations) and `simulate.pictures.export` (VTK time series) use
nothing else. The fabric layer stack, the Velostat film between its ITO sheets and the 6 x 6 N-type
elements with their three columns plug in here.

Coordinates are world metres as in the recording: pad centred on x = y = 0, its bottom at z = 0 and its
top at z = thickness; the indenter `position` channel is its lowest point.
"""

from __future__ import annotations

import importlib
from typing import Any

import numpy as np

from simulate.pictures.fields import EpisodeView, config_section

# family -> "module:Class"; one line per family
GEOMETRIES: dict[str, str] = {
    "cnt_pdms": "simulate.pictures.geometry:PadGeometry",
    "fabric": "simulate.pictures.geometry_families:FabricStackGeometry",
    "velostat": "simulate.pictures.geometry_families:VelostatFilmGeometry",
    "ntype": "simulate.pictures.geometry_families:NtypeArrayGeometry",
}


class FamilyGeometry:
    """Interface. Built once per episode view; `body` is called per frame.

    body(deformation_m (N,), point_fields {name: (n,) SI}, scale, index=k) -> pyvista dataset of the sensing
        body, deformed by `scale` x the deflection, with each field as point data and the true (unscaled)
        displacement vectors in point data "displacement" (m). `index` is the sample (for families that
        draw more recorded state than the deformation field, e.g. the N-type top electrodes).
    static_parts() -> [(mesh, add_mesh kwargs)]: layers that do not deform (electrodes, substrate, sheets).
    frame_parts(deformation_m, scale, index, field) -> [(mesh, add_mesh kwargs)]: parts redrawn every frame
        that are not coloured by the field (a translucent sheet over the film, columns under a skin).
    top_z_m: height of the contact surface as drawn; size_m: (x, y, z) extent as drawn, for the camera.
    real_top_z_m: the true height of the contact surface (differs from top_z_m where `z_stretch` != 1).
    z_stretch: thin stacks are drawn this many times thicker than they are (stated on the picture); the
        export (display=False) always writes true geometry.
    caption: a line added under the picture (what is drawn how). smooth: smooth shading suits the body.
    peak_deflection_m: the largest deflection the body shows over the episode (sets the exaggeration).
    taxel_points(scale=0) -> (N, 3): where each taxel's value sits on the body (for tests and probes).
    """

    top_z_m: float
    size_m: tuple[float, float, float]
    z_stretch: float = 1.0
    caption: str = ""
    smooth: bool = True

    @property
    def real_top_z_m(self) -> float:
        return self.top_z_m / self.z_stretch

    @property
    def peak_deflection_m(self) -> float:
        return float(np.nanmax(self.view.deformation_m, initial=0.0)) if hasattr(self, "view") else 0.0

    def body(self, deformation_m: np.ndarray, point_fields: dict[str, np.ndarray], scale: float,
             index: int | None = None) -> Any:
        raise NotImplementedError

    def static_parts(self) -> list[tuple[Any, dict]]:
        return []

    def frame_parts(self, deformation_m: np.ndarray, scale: float, index: int, field: str) -> list[tuple[Any, dict]]:
        return []

    def taxel_points(self) -> np.ndarray:
        raise NotImplementedError


def make_geometry(view: EpisodeView, display: bool = True) -> FamilyGeometry:
    """The family's geometry for `view`; display=False: true proportions (no z_stretch), for the export."""
    fam = view.family
    if fam not in GEOMETRIES:
        raise ValueError(f"no geometry for sensor family '{fam}' (allowed: {', '.join(sorted(GEOMETRIES))})")
    module, cls = GEOMETRIES[fam].split(":")
    return getattr(importlib.import_module(module), cls)(view, display=display)


def _pv():
    from simulate.pictures.pyvista_setup import import_pyvista

    return import_pyvista()


def _padded_centres(length_m: float, n: int) -> np.ndarray:
    """Node coordinates: the pad edges plus the n taxel centres, (n + 2,)."""
    pitch = length_m / n
    c = -0.5 * length_m + (np.arange(n) + 0.5) * pitch
    return np.concatenate([[-0.5 * length_m], c, [0.5 * length_m]])


class PadGeometry(FamilyGeometry):
    """An elastomer pad (cnt_pdms): a box with a taxel grid on its top face.

    Nodes sit on the taxel centres (plus the pad edges, which copy the outermost taxel), so every taxel's
    recorded value is exactly a node value. The deflection d of the top decays linearly to zero at the
    bottom (a thin layer on a rigid base, uniform strain through the thickness as in the Winkler model).
    """

    n_layers = 4

    def __init__(self, view: EpisodeView, display: bool = True):
        self.view = view
        pad = config_section(view, "pad")
        self.lx, self.ly, self.h = float(pad["size_x_m"]), float(pad["size_y_m"]), float(pad["thickness_m"])
        self.nx, self.ny = int(pad["taxels_x"]), int(pad["taxels_y"])
        if self.nx * self.ny != view.deformation_m.shape[1]:
            raise ValueError(
                f"pad.taxels_x x taxels_y = {self.nx * self.ny} but the recording has {view.deformation_m.shape[1]} taxels"
            )
        self.top_z_m = self.h
        self.size_m = (self.lx, self.ly, self.h)
        xs = _padded_centres(self.lx, self.nx)
        ys = _padded_centres(self.ly, self.ny)
        zs = np.linspace(0.0, self.h, self.n_layers + 1)
        # (ny+2, nx+2, nz) index order; flattened x fastest, then y, then z
        self._z, self._y, self._x = np.meshgrid(zs, ys, xs, indexing="ij")
        self._zfrac = (self._z / self.h).ravel()
        # node (iy, ix) -> taxel index (edges copy the outermost taxel)
        iy = np.clip(np.arange(self.ny + 2) - 1, 0, self.ny - 1)
        ix = np.clip(np.arange(self.nx + 2) - 1, 0, self.nx - 1)
        col = (iy[:, None] * self.nx + ix[None, :]).ravel()  # (ny+2)(nx+2)
        self._node_taxel = np.tile(col, self.n_layers + 1)
        self._ref = np.stack([self._x.ravel(), self._y.ravel(), self._z.ravel()], axis=1)
        self._dims = (self.nx + 2, self.ny + 2, self.n_layers + 1)

    def body(self, deformation_m, point_fields, scale, index=None):
        pv = _pv()
        d = np.asarray(deformation_m, dtype=np.float64)[self._node_taxel] * self._zfrac  # (P,), + down
        disp = np.zeros_like(self._ref)
        disp[:, 2] = -d
        grid = pv.StructuredGrid()
        grid.points = self._ref + scale * disp
        grid.dimensions = self._dims  # points are x fastest, then y, then z: VTK's order
        grid.point_data["displacement"] = disp
        for name, vals in point_fields.items():
            grid.point_data[name] = np.asarray(vals, dtype=np.float64)[self._node_taxel]
        return grid

    def taxel_points(self) -> np.ndarray:
        """(N, 3) taxel centres on the undeformed top face (flat index iy * nx + ix)."""
        xs = _padded_centres(self.lx, self.nx)[1:-1]
        ys = _padded_centres(self.ly, self.ny)[1:-1]
        gx, gy = np.meshgrid(xs, ys)
        return np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, self.h)], axis=1)


def indenter_mesh(view: EpisodeView, k: int, top_z_m: float, scale: float, real_top_z_m: float | None = None):
    """The indenter at sample k, its penetration below `top_z_m` exaggerated by `scale` like the body.

    Box: a block of the configured footprint, 1.5 x its larger side tall; sphere: the configured radius.
    None when the recording has no indenter position. `real_top_z_m`: the true surface height when the
    body is drawn thicker than it is (top_z_m is then the drawn one); the gap above it is kept true.
    """
    pv = _pv()
    ind = config_section(view, "indenter")
    p = np.asarray(view.position_m[k], dtype=np.float64)
    if not np.all(np.isfinite(p)):
        return None
    real_top = top_z_m if real_top_z_m is None else real_top_z_m
    z = top_z_m + (p[2] - real_top)
    if p[2] < real_top:  # penetrating: drawn as deep as the exaggerated dent
        z = top_z_m - scale * (real_top - p[2])
    if ind.get("shape", "box") == "sphere":
        r = float(ind["radius_m"])
        return pv.Sphere(radius=r, center=(p[0], p[1], z + r), theta_resolution=32, phi_resolution=32)
    sx, sy = float(ind["size_x_m"]), float(ind["size_y_m"])
    hz = 1.5 * max(sx, sy)
    return pv.Box(bounds=(p[0] - sx / 2, p[0] + sx / 2, p[1] - sy / 2, p[1] + sy / 2, z, z + hz))
