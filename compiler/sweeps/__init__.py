"""Parameter sweeps (``sofac sweep``, :func:`sofac.sweep`): runs as Dask tasks, results as NetCDF."""
