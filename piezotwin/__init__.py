"""piezotwin: the command line (thin; the work lives in scenes, sensors, simulate, learn)."""
