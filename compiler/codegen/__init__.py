"""Code generation: Plan -> C++ source. The only stage that writes C++ text."""
