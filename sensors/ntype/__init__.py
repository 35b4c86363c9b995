"""N-type 6 x 6 three-dimensional force array (paper key `ntype`): model, numpy reference, Warp kernels."""
