"""Load stage: shared library -> Simulation (numpy views of the native state), run specs and
warm records."""
