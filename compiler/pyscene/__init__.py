"""SofaPython3 scenes: a script defining createScene(rootNode) runs against sofac's own
SofaPython3-compatible API (sofa_api), builds the scene model the pipeline compiles, and its
controllers run between compiled steps (script)."""
