"""The lowerings, by component family: the spec of a component (its ``kernel`` field) names the
function here that turns it into calls of the step.
"""

from __future__ import annotations

from sofac.plan.lower.beams import lower_beam_fem, lower_beam_linear_mapping
from sofac.plan.lower.common import Lowering
from sofac.plan.lower.constraint_models import (
    lower_bilateral,
    lower_fixed_lagrangian,
    lower_sliding,
    lower_stopper,
    lower_uniform,
)
from sofac.plan.lower.constraints import lower_constraint_correction, lower_constraint_solver
from sofac.plan.lower.fem import (
    lower_element_fem,
    lower_fast_tetra_fem,
    lower_fem,
    lower_quad_bending,
    lower_triangle_fem,
    lower_trifem_optim,
)
from sofac.plan.lower.hyperelastic import lower_hyperelastic
from sofac.plan.lower.loads import (
    lower_constant_force,
    lower_edge_pressure,
    lower_interaction_ellipsoid,
    lower_plane_force,
    lower_rest_shape,
    lower_triangle_pressure,
    lower_velocity_damping,
)
from sofac.plan.lower.mappings import (
    lower_barycentric_mapping,
    lower_distance_mapping,
    lower_distance_multi_mapping,
    lower_rigid_mapping,
    lower_subset_mapping,
)
from sofac.plan.lower.masses import (
    lower_diagonal_mass,
    lower_fem_mass,
    lower_mesh_matrix_mass,
    lower_uniform_mass,
)
from sofac.plan.lower.projective import (
    lower_direction,
    lower_fixed,
    lower_fixed_plane,
    lower_fixed_rotation,
    lower_fixed_translation,
    lower_line_or_plane,
    lower_linear_movement,
    lower_linear_velocity,
    lower_partial_fixed,
    lower_point_constraint,
)
from sofac.plan.lower.springs import (
    lower_bending_springs,
    lower_grid_springs,
    lower_joint_springs,
    lower_mesh_springs,
    lower_quad_bending_springs,
    lower_quadular_bending_springs,
    lower_springs,
    lower_triangular_bending_springs,
    lower_vector_springs,
)

LOWERINGS: dict[str, Lowering] = {
    "grid_springs": lower_grid_springs,
    "element_fem": lower_element_fem,
    "fem_mass": lower_fem_mass,
    "mesh_matrix_mass": lower_mesh_matrix_mass,
    "tetra_fem": lower_fem,
    "tetracorot_fem": lower_fem,
    "hexa_fem": lower_fem,
    "hexahedral_fem": lower_fem,
    "fast_tetra_fem": lower_fast_tetra_fem,
    "trifem": lower_fem,
    "trifem_optim": lower_trifem_optim,
    "triangle_fem": lower_triangle_fem,
    "quad_bending": lower_quad_bending,
    "hyperelastic": lower_hyperelastic,
    "quad_bending_springs": lower_quad_bending_springs,
    "quadular_bending_springs": lower_quadular_bending_springs,
    "triangular_bending_springs": lower_triangular_bending_springs,
    "interaction_ellipsoid": lower_interaction_ellipsoid,
    "distance_mapping": lower_distance_mapping,
    "distance_multi_mapping": lower_distance_multi_mapping,
    "velocity_damping": lower_velocity_damping,
    "bending_springs": lower_bending_springs,
    "barycentric_mapping": lower_barycentric_mapping,
    "uniform_mass": lower_uniform_mass,
    "diagonal_mass": lower_diagonal_mass,
    "springs": lower_springs,
    "mesh_springs": lower_mesh_springs,
    "vector_springs": lower_vector_springs,
    "joint_springs": lower_joint_springs,
    "constant_force": lower_constant_force,
    "rest_shape_springs": lower_rest_shape,
    "fixed": lower_fixed,
    "partial_fixed": lower_partial_fixed,
    "line_or_plane": lower_line_or_plane,
    "point_constraint": lower_point_constraint,
    "linear_velocity": lower_linear_velocity,
    "linear_movement": lower_linear_movement,
    "fixed_plane": lower_fixed_plane,
    "fixed_translation": lower_fixed_translation,
    "fixed_rotation": lower_fixed_rotation,
    "direction": lower_direction,
    "plane_force": lower_plane_force,
    "triangle_pressure": lower_triangle_pressure,
    "edge_pressure": lower_edge_pressure,
    "rigid_mapping": lower_rigid_mapping,
    "identity_mapping": lower_subset_mapping,
    "subset_mapping": lower_subset_mapping,
    "constraint_solver": lower_constraint_solver,
    "constraint_correction": lower_constraint_correction,
    "bilateral_constraint": lower_bilateral,
    "fixed_lagrangian_constraint": lower_fixed_lagrangian,
    "stopper_constraint": lower_stopper,
    "sliding_constraint": lower_sliding,
    "uniform_constraint": lower_uniform,
    "beam_fem": lower_beam_fem,
    "beam_linear_mapping": lower_beam_linear_mapping,
}
