"""The developers' benchmarks and long studies (outside the installed package): the hot paths against named
baselines (``benchmarks``, ``baselines``), negstiff against the tools a user would pick instead (``peers``),
what a user waits for (``waits``), the UQ calibration study on a dask cluster (``uq_calibration``) and the
record walk (``record_walk``). Run from the repository, e.g. ``python -m benchmarks.benchmarks``;
``pip install -e '.[bench]'`` installs what they need.
"""
