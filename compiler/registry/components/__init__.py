"""Component families. Each module defines ``COMPONENTS``, a tuple of ComponentSpec."""
