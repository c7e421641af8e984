"""SOFA's regression suite (suite) and its state files (states)."""
