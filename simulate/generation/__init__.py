"""Generation: the run loop, shards over processes or machines (executors), and the GPU feed."""
