"""Compile-time geometry shared by the check and plan stages: barycentric mappers, voxelised grids,
FEM cell splits, mass matrices, bending springs, element FEM data."""
