"""Velostat film with ITO position layers (paper key `velostat`): model, numpy reference, Warp kernels, fit."""
