"""VTK time series of a recorded episode for ParaView: one .vtu per sample (body, and indenter when recorded)
plus a .pvd collection that holds the times.

Points are the undeformed geometry (m) with point data "displacement" (m, the true deflection: use
ParaView's *Warp By Vector* with a scale factor to see it) and every field in SI units as recorded
(deformation m, pressure Pa, strain 1, resistance ohm, force_taxel N; NaN where a field has no value, e.g.
the N-type column fields on the top surface). Thin stacks are written at their true thickness (the
pictures' z stretch is not applied). Field data: time (s), force (N).
Layout::

    DIR/<episode>.pvd
    DIR/<episode>/body_000000.vtu ...        part 0
    DIR/<episode>/indenter_000000.vtu ...    part 1 (true position, not exaggerated)
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

from simulate.pictures.fields import EpisodeView
from simulate.pictures.geometry import indenter_mesh, make_geometry


def export_episode(
    view: EpisodeView,
    out_dir: str | Path,
    *,
    stride: int = 1,
    on_frame: Callable[[int, int], None] | None = None,
) -> Path:
    """Write the episode's time series under out_dir; returns the .pvd path."""
    from simulate.pictures.pyvista_setup import import_pyvista

    import_pyvista()
    out = Path(out_dir)
    sub = out / view.ep_id
    sub.mkdir(parents=True, exist_ok=True)
    geom = make_geometry(view, display=False)
    idx = np.arange(0, view.n_samples, max(1, int(stride)))
    entries: list[str] = []
    for j, k in enumerate(idx):
        k = int(k)
        t = float(view.time_s[k])
        body = geom.body(view.deformation_m[k], {n: v[k] for n, v in view.fields.items()}, 0.0, index=k)
        grid = body.cast_to_unstructured_grid()
        grid.field_data["time"] = np.array([t])
        grid.field_data["force"] = np.array([float(view.force_n[k])])
        name = f"body_{k:06d}.vtu"
        grid.save(sub / name, binary=True)
        entries.append(_entry(t, 0, f"{view.ep_id}/{name}"))
        ind = indenter_mesh(view, k, geom.top_z_m, 1.0)
        if ind is not None:
            iname = f"indenter_{k:06d}.vtu"
            ind.cast_to_unstructured_grid().save(sub / iname, binary=True)
            entries.append(_entry(t, 1, f"{view.ep_id}/{iname}"))
        if on_frame:
            on_frame(j + 1, len(idx))
    pvd = out / f"{view.ep_id}.pvd"
    pvd.write_text(
        '<?xml version="1.0"?>\n'
        '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">\n'
        "  <Collection>\n" + "\n".join(entries) + "\n  </Collection>\n</VTKFile>\n"
    )
    return pvd


def _entry(t: float, part: int, file: str) -> str:
    return f'    <DataSet timestep="{t!r}" group="" part="{part}" file={quoteattr(file)}/>'
