"""The recording format and what reads it: HDF5 shards, the manifest, torch windows, real-log import, resampling."""
