"""Knitted conductive fabric stacks (paper key `fabric`): model, numpy reference, Warp kernels, calibration."""
