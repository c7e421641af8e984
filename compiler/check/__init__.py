"""Check stage: Scene -> CheckedScene (types, links, templates, mappings), with diagnostics at
file, line and attribute. Never compiles anything."""
