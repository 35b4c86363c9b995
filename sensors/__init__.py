"""sensors: transduction physics (Warp kernels + numpy references), electronics, recordings, datasets."""
