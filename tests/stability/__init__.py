"""Stability suite: hard scenes with their expected outcomes, property-based runs, determinism."""
