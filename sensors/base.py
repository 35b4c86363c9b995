"""What every sensor model shares: the load it receives from simulate, its output specs, and the protocol
a family model implements (Isaac Lab TacSL-style config / sensor / data triad: the config is
scenes.SceneConfig, the sensor is a class here, the data are the arrays below)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np


@dataclass(frozen=True)
class ChannelSpec:
    """How an output is stored: units and dimension names (first dim after episode is time)."""

    units: str
    dims: tuple[str, ...]
    description: str


@dataclass
class LoadBatch:
    """Load field of E episodes x T samples on N taxels (float64, SI).

    time_s: (T,) sample times, sample k at k / sample_rate_hz.
    target: (E, T) commanded penetration (m, + into the pad) or force (N, + compressive).
    indenter_pos_m: (E, T, 3) world position of the indenter's lowest point on its axis (box: bottom-face
        centre, sphere: bottom pole); z - pad thickness = -penetration.
    contact_force_n: (E, T, 3) net contact force of the indenter on the pad, world x/y (tangential, force
        on the pad) and z = normal compressive force (positive when pressing; = -F_z on the pad).
    contact_points: (E, T) number of MuJoCo contacts between indenter and pad.
    deformation_m: (E, T, N) surface deflection of the pad (m, + down).
    pressure_pa: (E, T, N) normal pressure; sum over N of pressure * taxel_area == contact_force_n[..., 2].
    shear_pa: (E, T, N, 2) tangential traction on the pad (x, y); sums to contact_force_n[..., :2] / area.
    taxel_xy_m: (N, 2) taxel centres, flat index n = iy * taxels_x + ix.
    taxel_area_m2: area of one taxel cell.
    control: "displacement" | "force".

    On the GPU path (`simulate.contact.load_field.iter_load_batches(device_fields=...)`) deformation_m, pressure_pa and
    shear_pa may instead be Warp arrays on the sensor's device, flat over frames: (E T, N), (E T, N, 2);
    only a sensor with `device_load = True` is given those; `on_host()` makes the numpy form.
    """

    time_s: np.ndarray
    target: np.ndarray
    indenter_pos_m: np.ndarray
    contact_force_n: np.ndarray
    contact_points: np.ndarray
    deformation_m: np.ndarray
    pressure_pa: np.ndarray
    shear_pa: np.ndarray
    taxel_xy_m: np.ndarray
    taxel_area_m2: float
    control: str

    @property
    def fields_on_device(self) -> bool:
        return not isinstance(self.deformation_m, np.ndarray) and not getattr(self.deformation_m, "on_host", False)

    def on_host(self) -> LoadBatch:
        """This batch with the taxel fields as numpy arrays (E, T, N) / (E, T, N, 2) (a no-op on the host)."""
        if not self.fields_on_device:
            return self
        from dataclasses import replace

        E, T = self.target.shape
        return replace(self, deformation_m=self.deformation_m.numpy().reshape(E, T, -1),
                       pressure_pa=self.pressure_pa.numpy().reshape(E, T, -1),
                       shear_pa=self.shear_pa.numpy().reshape(E, T, -1, 2))


class SensorModel(Protocol):
    """A sensor family's batched model. Shapes: E episodes, T samples."""

    family: str
    outputs: dict[str, ChannelSpec]

    def run_load(self, load: LoadBatch, seeds: list[int]) -> dict[str, np.ndarray]:
        """Load field of E episodes -> {output name: array [E, T, ...]} (names and units in `outputs`)."""
        ...

    def attrs(self) -> dict:
        """/sensor attrs for recordings (family, geometry in m, sample rate, ADC...)."""
        ...


def resolve_backend(backend: str, device: str) -> str:
    """Check a sensor's backend ("warp" | "numpy") and return the Warp device it runs on."""
    if backend not in ("warp", "numpy"):
        raise ValueError(f"backend must be 'warp' or 'numpy'; got {backend!r}")
    if backend == "numpy":
        return device
    from sensors.warp_setup import resolve_device

    return resolve_device(device)
