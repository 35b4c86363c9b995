"""CNT-PDMS soft taxels (paper key `cnt_pdms`): model, flat parameters, numpy reference, Warp kernels."""
