"""Finite-element force fields (linear elasticity on tetrahedra, hexahedra, triangles, beams)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from ..fields import Bool, Color, Coords, Enum, Int, Ints, Options, Real, Reals, Text
from ..spec import Category, ComponentSpec, Effect, FieldSpec, Variant
from .common import (
    ELASTICITY_FIELDS,
    ELEMENT_TEMPLATES,
    FORCEFIELD_FIELDS,
    MASS_FIELDS,
    MASS_ONLY_FIELDS,
    MUST_BE_IN_UNIT_INTERVAL,
    MUST_BE_NONNEGATIVE,
    MUST_BE_POSITIVE,
    POISSON_RATIO,
    TOPOLOGY_LINK,
)

_MODULE = "Sofa.Component.SolidMechanics.FEM.Elastic"
_FEM_EFFECTS = frozenset({Effect.INTERNAL_FORCE, Effect.STIFFNESS})
_BEAMS = "beam elements are not supported yet"

_VON_MISES = FieldSpec(
    "computeVonMisesStress", Int(), 0, "von Mises stress: 0 none, 1 from the corotational strain, 2 full"
)
# float(numpy.float32(0.0001)) and float(numpy.float32(0.9)): SOFA's float literals as doubles
_FLOAT_0_0001 = 9.999999747378752e-05
_FLOAT_0_9 = 0.8999999761581421
_GATHER = (
    FieldSpec("gatherPt", Text(), doc="GPU version only: DOFs gathered per thread"),
    FieldSpec("gatherBsize", Text(), doc="GPU version only: gather block size"),
)

# drawColor1..4 of the tetrahedral corotational force fields (display only)
_TETRA_DRAW_COLORS = tuple(
    FieldSpec(f"drawColor{i}", Color(), c)
    for i, c in enumerate(
        ((0.0, 0.0, 1.0, 1.0), (0.0, 0.5, 1.0, 1.0), (0.0, 1.0, 1.0, 1.0), (0.5, 1.0, 1.0, 1.0)), start=1
    )
)

TETRAHEDRON_FEM_FORCE_FIELD = ComponentSpec(
    name="TetrahedronFEMForceField",
    lowering="tetra_fem",
    category=Category.FORCEFIELD,
    module=_MODULE,
    doc="Linear tetrahedra (constant strain), small or corotational (large/polar/svd). Uses the "
    "topology's tetrahedra, or splits its hexahedra into 6 tetrahedra each.",
    templates=("Vec3d",),
    default_template="Vec3d",
    supported=True,
    effects=_FEM_EFFECTS,
    fields=(
        FieldSpec(
            "method",
            Enum(values=("large", "small", "polar", "svd"), case_sensitive=True),
            "large",
            "small displacements, or corotational with rotations from QR (large), polar or SVD",
        ),
        FieldSpec(
            "localStiffnessFactor",
            Reals(),
            doc="per-element stiffness factors (cycled)",
            valid=MUST_BE_NONNEGATIVE,
        ),
        FieldSpec("updateStiffnessMatrix", Bool(), False, "recompute element stiffness every step"),
        FieldSpec(
            "computeGlobalMatrix",
            Bool(),
            False,
            "assemble a global stiffness matrix",
            aliases=("assembling",),
        ),
        # SOFA's defaults are float literals ((Real)0.0001f, (Real)0.9f): their double values here
        FieldSpec("plasticMaxThreshold", Real(), 0.0, "plasticity: maximum plastic strain (2-norm)"),
        FieldSpec("plasticYieldThreshold", Real(), _FLOAT_0_0001, "plasticity: yield strain (2-norm)"),
        FieldSpec(
            "plasticCreep",
            Real(),
            _FLOAT_0_9,
            "plasticity: creep factor times dt",
            valid=MUST_BE_IN_UNIT_INTERVAL,
        ),
        FieldSpec("initialPoints", Coords(), doc="rest positions (default: the state's)"),
        FieldSpec("updateStiffness", Bool(), False, "recompute precomputed data from changed parameters"),
        _VON_MISES,
        FieldSpec("vonMisesPerElement", Reals(), doc="output: von Mises stress per element"),
        FieldSpec("vonMisesPerNode", Reals(), doc="output: von Mises stress per node"),
        FieldSpec("vonMisesStressColors", Reals(), doc="output: display colors"),
        FieldSpec("showStressColorMap", Text(), "Blue to Red", "color map for stress display"),
        FieldSpec("showStressAlpha", Real(), 1.0),
        FieldSpec("showVonMisesStressPerNode", Bool(), False),
        FieldSpec("showVonMisesStressPerNodeColorMap", Bool(), False),
        FieldSpec("showVonMisesStressPerElement", Bool(), False),
        FieldSpec("showElementGapScale", Real(), 0.333),
        FieldSpec("drawHeterogeneousTetra", Bool(), False),
        *_GATHER,
        *ELASTICITY_FIELDS,
    ),
)

TETRAHEDRAL_COROTATIONAL_FEM_FORCE_FIELD = ComponentSpec(
    name="TetrahedralCorotationalFEMForceField",
    lowering="tetracorot_fem",
    category=Category.FORCEFIELD,
    module=_MODULE,
    doc="Corotational linear tetrahedra on a dynamic TetrahedronSetTopology (same physics as "
    "TetrahedronFEMForceField large/polar).",
    templates=("Vec3d",),
    default_template="Vec3d",
    supported=True,
    effects=_FEM_EFFECTS,
    fields=(
        FieldSpec(
            "method",
            Enum(values=("large", "small", "polar"), case_sensitive=True),
            "large",
            "small displacements, or corotational with rotations from QR (large) or polar",
        ),
        FieldSpec(
            "localStiffnessFactor",
            Reals(),
            doc="per-element stiffness factors (cycled)",
            valid=MUST_BE_NONNEGATIVE,
        ),
        FieldSpec("updateStiffnessMatrix", Bool(), False, "recompute element stiffness every step"),
        FieldSpec(
            "computeGlobalMatrix",
            Bool(),
            False,
            "assemble a global stiffness matrix",
            aliases=("assembling",),
        ),
        _VON_MISES,
        FieldSpec("vonMisesPerElement", Reals(), doc="output: von Mises stress per element"),
        FieldSpec("vonMisesPerNode", Reals(), doc="output: von Mises stress per node"),
        FieldSpec("drawing", Bool(), True),
        *_TETRA_DRAW_COLORS,
        *ELASTICITY_FIELDS,
    ),
)

_HEXAHEDRON_FIELDS = (
    FieldSpec(
        "method",
        Enum(values=("large", "polar", "small"), case_sensitive=True),
        "large",
        "small displacements, or corotational with the element frame (large) or polar rotation",
    ),
    FieldSpec("updateStiffnessMatrix", Bool(), False, "recompute element stiffness every step"),
    FieldSpec("initialPoints", Coords(), doc="rest positions (default: the state's)"),
    FieldSpec("drawing", Bool(), True),
    FieldSpec("drawPercentageOffset", Real(), 0.15),
    *_GATHER,
    *ELASTICITY_FIELDS,
)

HEXAHEDRON_FEM_FORCE_FIELD = ComponentSpec(
    name="HexahedronFEMForceField",
    lowering="hexa_fem",
    category=Category.FORCEFIELD,
    module=_MODULE,
    doc="Trilinear hexahedra (8-node bricks), small or corotational, on the topology's hexahedra.",
    templates=("Vec3d",),
    default_template="Vec3d",
    supported=True,
    effects=_FEM_EFFECTS,
    fields=_HEXAHEDRON_FIELDS,
)

HEXAHEDRON_FEM_FORCE_FIELD_AND_MASS = ComponentSpec(
    name="HexahedronFEMForceFieldAndMass",
    lowering="hexa_fem",
    variant=Variant.AND_MASS,
    category=Category.MASS,
    module=_MODULE,
    doc="HexahedronFEMForceField plus the consistent (or lumped) mass of the same elements.",
    templates=("Vec3d",),
    default_template="Vec3d",
    supported=True,
    effects=frozenset({Effect.INERTIA, Effect.GRAVITY, Effect.INTERNAL_FORCE, Effect.STIFFNESS}),
    fields=(
        FieldSpec("density", Real(), 1.0, "mass per unit volume", valid=MUST_BE_POSITIVE),
        FieldSpec("lumpedMass", Bool(), False, "lump the element masses onto the diagonal"),
        *_HEXAHEDRON_FIELDS,
        *MASS_ONLY_FIELDS,
    ),
)

FAST_TETRAHEDRAL_COROTATIONAL_FORCE_FIELD = ComponentSpec(
    name="FastTetrahedralCorotationalForceField",
    lowering="fast_tetra_fem",
    category=Category.FORCEFIELD,
    module=_MODULE,
    doc="Corotational linear tetrahedra written on the topology's edges (runtime/sofac/"
    "fast_tetra_fem.h): rotations by QR of two edges (qr, large), polar decomposition of the "
    "deformation gradient (polar) or of the edges from vertex 0 (polar2), or none (none, linear, "
    "small). SOFA has no energy for it.",
    templates=("Vec3d",),
    default_template="Vec3d",
    supported=True,
    effects=_FEM_EFFECTS,
    fields=(
        FieldSpec(
            "method",
            Enum(values=("qr", "large", "polar", "polar2", "none", "linear", "small"), case_sensitive=True),
            "qr",
            "how element rotations are found",
        ),
        FieldSpec("drawing", Bool(), True),
        *_TETRA_DRAW_COLORS,
        *ELASTICITY_FIELDS,
    ),
)

HEXAHEDRAL_FEM_FORCE_FIELD = ComponentSpec(
    name="HexahedralFEMForceField",
    lowering="hexahedral_fem",
    category=Category.FORCEFIELD,
    module=_MODULE,
    doc="Corotational trilinear hexahedra (large or polar) with SOFA's closed-form element stiffness "
    "for axis-aligned boxes (runtime/sofac/hexahedral_fem.h); SOFA has no energy for it and "
    "assembles its stiffness with the rotation transposed (kept).",
    templates=("Vec3d",),
    default_template="Vec3d",
    supported=True,
    effects=_FEM_EFFECTS,
    fields=(
        FieldSpec(
            "method",
            Enum(values=("large", "polar"), case_sensitive=True),
            "large",
            "corotational frame: mean edges orthonormalised (large) or their polar rotation",
        ),
        *ELASTICITY_FIELDS,
    ),
)

TRIANGULAR_FEM_FORCE_FIELD = ComponentSpec(
    name="TriangularFEMForceField",
    lowering="trifem",
    category=Category.FORCEFIELD,
    module=_MODULE,
    doc="Constant-strain membrane triangles (plane stress) on a TriangleSetTopology, corotational for "
    "'large'.",
    templates=("Vec3d",),
    default_template="Vec3d",
    supported=True,
    effects=_FEM_EFFECTS,
    fields=(
        FieldSpec(
            "method",
            Enum(values=("large", "small"), case_sensitive=True),
            "large",
            "small or large (corotational) displacements",
        ),
        FieldSpec("hosfordExponant", Real(), 1.0, "exponent of the Hosford yield criterion"),
        FieldSpec("criteriaValue", Real(), 1e15, "fracture threshold (display)"),
        FieldSpec("computePrincipalStress", Bool(), False),
        FieldSpec("showStressValue", Bool(), True),
        FieldSpec("showStressVector", Bool(), False),
        FieldSpec("showFracturableTriangles", Bool(), False),
        FieldSpec("id", Real(), 0.0, "element followed in the graphs"),
        *ELASTICITY_FIELDS,
    ),
)

TRIANGULAR_FEM_FORCE_FIELD_OPTIM = ComponentSpec(
    name="TriangularFEMForceFieldOptim",
    lowering="trifem_optim",
    category=Category.FORCEFIELD,
    module=_MODULE,
    doc="Optimised corotational membrane triangles (large displacements only).",
    templates=("Vec3d",),
    default_template="Vec3d",
    supported=True,
    effects=_FEM_EFFECTS,
    fields=(
        FieldSpec(
            "method",
            Enum(values=("large", "small"), case_sensitive=True),
            "large",
            "only 'large' is implemented; SOFA ignores other values with a warning",
        ),
        FieldSpec("damping", Real(), 0.0, "damping / stiffness ratio", valid=MUST_BE_NONNEGATIVE),
        FieldSpec("restScale", Real(), 1.0, "scale of the rest shape (pre-stretch)", valid=MUST_BE_POSITIVE),
        FieldSpec("computePrincipalStress", Bool(), False),
        FieldSpec("stressMaxValue", Real(), 0.0, "output: maximum stress"),
        FieldSpec("showStressVector", Bool(), False),
        FieldSpec("showStressThreshold", Real(), 0.0),
        *ELASTICITY_FIELDS,
    ),
)

TRIANGLE_FEM_FORCE_FIELD = ComponentSpec(
    name="TriangleFEMForceField",
    lowering="triangle_fem",
    category=Category.FORCEFIELD,
    module=_MODULE,
    doc="Constant-strain triangles on a static topology (its triangles, or two per quad), plane "
    "stress (or plane strain), corotational for 'large'; SOFA's 'small' works in the world x, y "
    "plane. SOFA has no energy for it.",
    templates=("Vec3d",),
    default_template="Vec3d",
    supported=True,
    effects=_FEM_EFFECTS,
    fields=(
        FieldSpec(
            "method",
            Enum(values=("large", "small"), case_sensitive=True),
            "large",
            "small or large (corotational) displacements",
        ),
        FieldSpec("thickness", Real(), 1.0, "membrane thickness", valid=MUST_BE_POSITIVE),
        FieldSpec("planeStrain", Bool(), False, "plane strain instead of plane stress"),
        FieldSpec("initialPoints", Coords(), doc="rest positions (default: the state's)"),
        *ELASTICITY_FIELDS,
    ),
)

# Element-based FEM framework (template "DataType,ElementType").
_ELEMENT_FEM_FIELDS = (
    FieldSpec(
        "computeForceStrategy",
        Enum(values=("parallel", "sequenced")),
        "parallel",
        "run the force computation in parallel or sequentially",
    ),
    FieldSpec(
        "computeForceDerivStrategy",
        Enum(values=("parallel", "sequenced")),
        "parallel",
        "run the force-derivative computation in parallel or sequentially",
    ),
    FieldSpec("elementSpace", Real(), 0.125, "display gap between elements"),
    FieldSpec("elementStiffness", Reals(), doc="output: element stiffness matrices"),
    *ELASTICITY_FIELDS,
)

COROTATIONAL_FEM_FORCE_FIELD = ComponentSpec(
    name="CorotationalFEMForceField",
    variant=Variant.COROTATIONAL,
    lowering="element_fem",
    category=Category.FORCEFIELD,
    module=_MODULE,
    doc="Corotational linear elasticity for one element type, chosen by the second template "
    'argument (e.g. template="Vec3,Tetrahedron").',
    templates=ELEMENT_TEMPLATES,
    default_template=ELEMENT_TEMPLATES[0],
    supported=True,
    effects=_FEM_EFFECTS,
    fields=(
        FieldSpec(
            "rotationMethod",
            Enum(values=("stable_polar", "polar", "identity", "triangle", "hexahedron"), case_sensitive=True),
            doc="how element rotations are found (default: triangle for triangles and tetrahedra, "
            "hexahedron for hexahedra, stable_polar otherwise)",
        ),
        *_ELEMENT_FEM_FIELDS,
    ),
)

LINEAR_SMALL_STRAIN_FEM_FORCE_FIELD = ComponentSpec(
    name="LinearSmallStrainFEMForceField",
    lowering="element_fem",
    category=Category.FORCEFIELD,
    module=_MODULE,
    doc="Small-strain linear elasticity for one element type, chosen by the second template argument.",
    templates=ELEMENT_TEMPLATES,
    default_template=ELEMENT_TEMPLATES[0],
    supported=True,
    effects=_FEM_EFFECTS,
    fields=_ELEMENT_FEM_FIELDS,
)

QUAD_BENDING_FEM_FORCE_FIELD = ComponentSpec(
    name="QuadBendingFEMForceField",
    category=Category.FORCEFIELD,
    module=_MODULE,
    lowering="quad_bending",
    doc="Quad plate elements in world coordinates: a bilinear membrane on x, y and the transverse "
    "shear of w with the rotations held at zero (SOFA's small method, runtime/sofac/quad_bending.h).",
    templates=("Vec3d",),
    default_template="Vec3d",
    supported=True,
    effects=_FEM_EFFECTS,
    fields=(
        FieldSpec(
            "method",
            Enum(values=("small", "large"), case_sensitive=True),
            "small",
            "SOFA reads it nowhere: every quad uses the small-displacement method",
        ),
        FieldSpec(
            "youngModulus",
            Reals(),
            (1000.0,),
            "Young's modulus (one, or per element)",
            valid=MUST_BE_POSITIVE,
        ),
        FieldSpec(
            "poissonRatio", Reals(), (0.45,), "Poisson's ratio (one, or per element)", valid=POISSON_RATIO
        ),
        FieldSpec("thickness", Real(), 1.0, "plate thickness", valid=MUST_BE_POSITIVE),
        *FORCEFIELD_FIELDS,
        TOPOLOGY_LINK,
    ),
)

# SOFA's materialName options, in SOFA's order (the runtime's material codes, hyperelastic.h), and
# the ParameterSet each compiled material reads (SOFA reads parameterArray[i] unchecked).
HYPERELASTIC_MATERIALS = (
    "ArrudaBoyce",
    "StVenantKirchhoff",
    "NeoHookean",
    "MooneyRivlin",
    "VerondaWestman",
    "Costa",
    "Ogden",
    "StableNeoHookean",
)
HYPERELASTIC_PARAMETERS: dict[str, tuple[str, ...]] = {
    "ArrudaBoyce": ("mu", "k0"),
    "StVenantKirchhoff": ("mu", "lambda"),
    "NeoHookean": ("mu", "lambda"),
    "MooneyRivlin": ("c1", "c2", "k0"),
    "VerondaWestman": ("c1", "c2", "k0"),
    "Costa": ("a", "k0", "bff", "bfs", "bss", "bfn", "bsn", "bnn"),
    "Ogden": ("mu1", "alpha1", "k0"),
    "StableNeoHookean": ("mu", "lambda"),
}


def hyperelastic_problem(material: str, parameters: Sequence[float]) -> tuple[str, str, str, str] | None:
    """Why a material and ParameterSet cannot be compiled, as (code, attribute, message, hint);
    None when they can."""
    names = HYPERELASTIC_PARAMETERS.get(material)
    compiled = ", ".join(HYPERELASTIC_PARAMETERS)
    if names is None:
        return (
            "E222",
            "materialName",
            f"unsupported material {material!r}: it is not compiled yet",
            f"use one of {compiled}",
        )
    wanted = " ".join(names)
    if len(parameters) < len(names):
        given = "no ParameterSet" if not len(parameters) else f"ParameterSet has {len(parameters)} numbers"
        return (
            "E205",
            "ParameterSet",
            f"material {material} reads {len(names)} parameters ({wanted}), {given}",
            f'write ParameterSet="{wanted}" with numbers (SOFA reads them unchecked)',
        )
    if material == "Ogden" and parameters[1] == 0:
        return ("E207", "ParameterSet", "Ogden's alpha1 (the second number) is 0", "give alpha1 != 0")
    return None


def _hyperelastic_rule(value: Callable[[str], Any]) -> tuple[str, str, str, str] | None:
    written = value("ParameterSet")
    parameters = [] if written is None else [float(x) for x in np.ravel(written)]
    return hyperelastic_problem(str(value("materialName") or "ArrudaBoyce"), parameters)


TETRAHEDRON_HYPERELASTICITY_FEM_FORCE_FIELD = ComponentSpec(
    name="TetrahedronHyperelasticityFEMForceField",
    category=Category.FORCEFIELD,
    module="Sofa.Component.SolidMechanics.FEM.HyperElastic",
    doc="Hyperelastic tetrahedra (Neo-Hookean, Mooney-Rivlin, St Venant-Kirchhoff, Ogden, ...): "
    "ParameterSet holds the material's parameters in SOFA's order (ArrudaBoyce, StVenantKirchhoff, "
    "NeoHookean, StableNeoHookean: mu and k0 or lambda; MooneyRivlin, VerondaWestman: c1 c2 k0; "
    "Ogden: mu1 alpha1 k0; Costa: a k0 bff bfs bss bfn bsn bnn). AnisotropyDirections, which no "
    "material of SOFA reads, and matrixRegularization, which SOFA does not use, change nothing.",
    lowering="hyperelastic",
    validate=_hyperelastic_rule,
    templates=("Vec3d",),
    default_template="Vec3d",
    supported=True,
    effects=_FEM_EFFECTS,
    fields=(
        FieldSpec(
            "materialName",
            Options(values=HYPERELASTIC_MATERIALS),
            "ArrudaBoyce",
            "material law",
        ),
        FieldSpec("ParameterSet", Reals(), doc="material parameters"),
        FieldSpec("AnisotropyDirections", Reals(), doc="anisotropy directions"),
        FieldSpec("matrixRegularization", Bool(), False, "regularise the stiffness matrix"),
        *FORCEFIELD_FIELDS,
        TOPOLOGY_LINK,
    ),
)

BEAM_FEM_FORCE_FIELD = ComponentSpec(
    name="BeamFEMForceField",
    category=Category.FORCEFIELD,
    module=_MODULE,
    doc="Timoshenko beams between consecutive rigid frames along the topology's edges.",
    templates=("Rigid3d",),
    default_template="Rigid3d",
    lowering="beam_fem",
    supported=True,
    effects=_FEM_EFFECTS,
    fields=(
        FieldSpec("radius", Real(), 0.1, "beam section radius", valid=MUST_BE_POSITIVE),
        FieldSpec("radiusInner", Real(), 0.0, "inner radius of hollow beams", valid=MUST_BE_NONNEGATIVE),
        FieldSpec("listSegment", Ints(), doc="beam segments used (default: all)"),
        FieldSpec("useSymmetricAssembly", Bool(), False),
        *ELASTICITY_FIELDS,
    ),
)

# BeamAdapter plugin (not part of SOFA's main repository).
_BEAM_ADAPTER = "BeamAdapter"

ADAPTIVE_BEAM_FORCE_FIELD_AND_MASS = ComponentSpec(
    name="AdaptiveBeamForceFieldAndMass",
    category=Category.MASS,
    module=_BEAM_ADAPTER,
    doc="BeamAdapter plugin: adaptive beam elements with their mass.",
    templates=("Rigid3d",),
    default_template="Rigid3d",
    unsupported_reason=f"{_BEAMS} (BeamAdapter plugin)",
    effects=frozenset({Effect.INERTIA, Effect.GRAVITY, Effect.INTERNAL_FORCE, Effect.STIFFNESS}),
    fields=(
        FieldSpec("computeMass", Bool(), True, "also compute the beam mass"),
        FieldSpec("massDensity", Real(), 1.0, "mass density", valid=MUST_BE_POSITIVE),
        FieldSpec("interpolation", Text(), doc="link to the BeamInterpolation"),
        *MASS_FIELDS,
    ),
)

BEAM_INTERPOLATION = ComponentSpec(
    name="BeamInterpolation",
    category=Category.UTILITY,
    module=_BEAM_ADAPTER,
    doc="BeamAdapter plugin: beam geometry and material shared by beam components.",
    templates=("Rigid3d",),
    default_template="Rigid3d",
    unsupported_reason=f"{_BEAMS} (BeamAdapter plugin)",
    fields=(
        FieldSpec("radius", Real(), doc="beam radius", valid=MUST_BE_POSITIVE),
        FieldSpec("defaultYoungModulus", Reals(), doc="Young's modulus per beam", valid=MUST_BE_POSITIVE),
        FieldSpec("defaultPoissonRatio", Reals(), doc="Poisson's ratio per beam", valid=POISSON_RATIO),
        TOPOLOGY_LINK,
    ),
)

COMPONENTS = (
    TETRAHEDRON_FEM_FORCE_FIELD,
    TETRAHEDRAL_COROTATIONAL_FEM_FORCE_FIELD,
    HEXAHEDRON_FEM_FORCE_FIELD,
    HEXAHEDRON_FEM_FORCE_FIELD_AND_MASS,
    HEXAHEDRAL_FEM_FORCE_FIELD,
    FAST_TETRAHEDRAL_COROTATIONAL_FORCE_FIELD,
    TRIANGULAR_FEM_FORCE_FIELD,
    TRIANGULAR_FEM_FORCE_FIELD_OPTIM,
    TRIANGLE_FEM_FORCE_FIELD,
    COROTATIONAL_FEM_FORCE_FIELD,
    LINEAR_SMALL_STRAIN_FEM_FORCE_FIELD,
    QUAD_BENDING_FEM_FORCE_FIELD,
    TETRAHEDRON_HYPERELASTICITY_FEM_FORCE_FIELD,
    BEAM_FEM_FORCE_FIELD,
    ADAPTIVE_BEAM_FORCE_FIELD_AND_MASS,
    BEAM_INTERPOLATION,
)
