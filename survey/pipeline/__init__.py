"""The survey as a job: a TOML config in, cells fanned out over dask, checkpoints, one NetCDF
archive out; and single-orbit workflows."""
