"""One orbit at a time: Dormand-Prince 8(5,3) with dense output, events, surfaces of
section, chaos indicators and the torus analysis. Knows nothing of TOML, dask or xarray."""
