"""Sources for the virtual serial board (sensors.serial.board): a preset simulated here, or a recording file."""

from __future__ import annotations

from pathlib import Path

from sensors.serial.board import (
    MEASURED,
    DeviceError,
    Source,
    as_2d,
    load_recording_source,
)


def load_source(source: str, channel: str | None = None, overrides: list[str] | None = None, seed: int = 0) -> Source:
    """A preset (simulated with the numpy backend, one episode) or a recording file's first episode."""
    p = Path(source)
    if p.suffix in (".h5", ".hdf5") or p.is_file():
        return load_recording_source(p, channel)
    from scenes import ConfigError, load_scene
    from sensors.data.manifest import episode_seed
    from sensors.registry import make_sensor
    from simulate.generation.run import simulate_episodes

    try:
        cfg = load_scene(source, list(overrides or []))
    except ConfigError as exc:
        raise DeviceError(str(exc)) from None
    sensor = make_sensor(cfg, "numpy")
    ch_name = channel or next(c for c in MEASURED if c in sensor.outputs)
    if ch_name not in sensor.outputs and ch_name not in ("force", "time"):
        raise DeviceError(f"preset {cfg.name}: no channel {ch_name!r} (has {', '.join(sensor.outputs)})")
    res = simulate_episodes(cfg, [episode_seed(cfg.generation.root_seed, seed)], ["ep"], sensor, indices=[seed])[0]
    c = res.channels[ch_name]
    return Source(as_2d(c.data), float(cfg.sampling.sample_rate_hz), c.units, ch_name, f"preset {cfg.name}")
