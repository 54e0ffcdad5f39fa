"""OGBench's pointmaze family (Park et al., ICLR 2025) on the ``ogbench`` package: dataset names, a generator
in OGBench's recipe and npz format, reading and checking dataset files, and the 5-task evaluation protocol."""
