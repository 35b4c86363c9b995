"""Field mappers of the fabric, velostat and ntype families (registered in simulate.pictures.fields.FIELD_MAPPERS).

Each maps a recorded channel onto the places the family's geometry (simulate.pictures.geometry_families) colours:
  fabric    one taxel per sample (the presets) and one readout channel: channels per taxel are used as
            they are; the stack's resistance (time, channel) is spread over the taxels.
  velostat  per-taxel channels (pressure, deformation) as they are; the single force channel's resistance
            (time,) is shown on the loaded cells (pressure > 0), NaN (blank) elsewhere and without touch.
  ntype     per-taxel channels (the cover's load field) as they are; per-column channels
            (time, element, column) become (time, element x 3), flat index 3 m + c, columns in the
            recorded order (R_x, R_y, R_z); strain is shown compression-positive like the other families.
"""

from __future__ import annotations

import numpy as np

from simulate.pictures.fields import FieldError, _default_mapper

OPEN_CIRCUIT_OHM = 1e11  # velostat records 1e12 ohm without touch


def fabric_field(rec, ep_id: str, channel: str):
    dims = rec.dim_names(ep_id, channel)
    if dims == ("time", "taxel"):
        return _default_mapper(rec, ep_id, channel)
    n = int(rec.sensor_attrs.get("n_taxels", 1))
    data = np.asarray(rec.read(ep_id, channel), dtype=np.float64)
    if dims == ("time", "channel") and data.shape[1] == 1 or dims == ("time",):
        data = data.reshape(data.shape[0], 1)
        layers = int(rec.sensor_attrs.get("layers", 1))
        return np.repeat(data, n, axis=1), (f"{channel}: the whole {layers}-layer stack reads one value "
                                            f"(one readout channel), shown on every layer")
    return _default_mapper(rec, ep_id, channel)


def velostat_field(rec, ep_id: str, channel: str):
    dims = rec.dim_names(ep_id, channel)
    if dims == ("time", "taxel"):
        return _default_mapper(rec, ep_id, channel)
    if dims == ("time",):
        v = np.asarray(rec.read(ep_id, channel), dtype=np.float64)
        p = np.asarray(rec.read(ep_id, "pressure"), dtype=np.float64)
        out = np.where(p > 0, v[:, None], np.nan)
        if channel.startswith("resistance"):
            out[v >= OPEN_CIRCUIT_OHM] = np.nan
        return out, f"{channel}: one force channel (film + ITO in series), shown on the loaded cells"
    raise FieldError(f"channel '{channel}' has dims {dims}; no mapping onto the velostat film")


def ntype_field(rec, ep_id: str, channel: str):
    dims = rec.dim_names(ep_id, channel)
    if dims == ("time", "taxel"):
        return _default_mapper(rec, ep_id, channel)
    if dims == ("time", "element", "column"):
        data = np.asarray(rec.read(ep_id, channel), dtype=np.float64)
        T, M, C = data.shape
        out = data.reshape(T, M * C)
        note = f"{channel}: each of the {M} elements' {C} columns (R_x, R_y, R_z)"
        if channel == "strain":
            out = -out
            note = "strain: column strain, compression positive (recorded negative), per column"
        return out, note
    raise FieldError(f"channel '{channel}' has dims {dims}; no mapping onto the ntype columns")
