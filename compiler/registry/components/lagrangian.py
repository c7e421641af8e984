"""The Lagrangian constraint pipeline: FreeMotionAnimationLoop, constraint solvers and corrections.

The loop, the solvers and the corrections compile (plan/lower/constraints.py: the constraint phase
of the plan), with the Bilateral, Fixed, Uniform, Stopper and Sliding models' rows; the
Unilateral model does not yet, and is refused clearly.
"""

from __future__ import annotations

from ..fields import Bool, Coords, Int, Ints, Link, LinkList, Real, Reals
from ..spec import Category, ComponentSpec, Effect, FieldSpec, Variant
from .common import (
    ANIMATION_LOOP_FIELDS,
    MSTATE_LINK,
    MUST_BE_NONNEGATIVE,
    MUST_BE_POSITIVE,
    PAIR_LINKS,
    TOPOLOGY_LINK,
)

_REASON = "Lagrangian constraint rows are not compiled yet (FreeMotionAnimationLoop without constraints is)"
_SOLVER_MODULE = "Sofa.Component.Constraint.Lagrangian.Solver"
_CORRECTION_MODULE = "Sofa.Component.Constraint.Lagrangian.Correction"
_SOLVE = frozenset({Effect.CONSTRAINT_SOLVE})

FREE_MOTION_ANIMATION_LOOP = ComponentSpec(
    name="FreeMotionAnimationLoop",
    category=Category.ANIMATION_LOOP,
    module="Sofa.Component.AnimationLoop",
    doc="Step with a free (unconstrained) motion, collision detection, then a constraint solve that "
    "corrects positions and velocities.",
    former_names=("FreeMotionMasterSolver",),
    supported=True,
    effects=frozenset({Effect.INTEGRATION, Effect.CONSTRAINT_SOLVE}),
    fields=(
        FieldSpec(
            "solveVelocityConstraintFirst", Bool(), False, "solve velocity constraints before positions"
        ),
        FieldSpec("threadSafeVisitor", Bool(), False),
        FieldSpec("parallelCollisionDetectionAndFreeMotion", Bool(), False),
        FieldSpec("parallelODESolving", Bool(), False),
        FieldSpec(
            "constraintSolver",
            Link("constraint_solver"),
            doc="constraint solver (default: found in the node)",
        ),
        *ANIMATION_LOOP_FIELDS,
    ),
)

_CONSTRAINT_CORRECTIONS = FieldSpec(
    "constraintCorrections",
    LinkList("constraint_correction"),
    doc="constraint corrections (default: all found)",
)

LCP_CONSTRAINT_SOLVER = ComponentSpec(
    name="LCPConstraintSolver",
    category=Category.CONSTRAINT_SOLVER,
    module=_SOLVER_MODULE,
    doc="Solves the contact LCP (with friction) by projected Gauss-Seidel.",
    supported=True,
    lowering="constraint_solver",
    variant=Variant.LCP,
    effects=_SOLVE,
    fields=(
        FieldSpec("displayDebug", Bool(), False),
        FieldSpec("initial_guess", Bool(), True, "warm start from the previous solution"),
        FieldSpec("build_lcp", Bool(), True, "assemble the full LCP"),
        FieldSpec("tolerance", Real(), 0.001, "residual threshold", valid=MUST_BE_NONNEGATIVE),
        FieldSpec("maxIt", Int(), 1000, "maximum Gauss-Seidel iterations", valid=MUST_BE_POSITIVE),
        FieldSpec("regularizationTerm", Real(), 0.0, "added to the compliance diagonal"),
        FieldSpec("mu", Real(), 0.6, "friction coefficient", valid=MUST_BE_NONNEGATIVE),
        FieldSpec("minW", Real(), 0.0),
        FieldSpec("maxF", Real(), 0.0),
        FieldSpec("computeConstraintForces", Bool(), False),
        FieldSpec("constraintForces", Reals(), doc="output: constraint forces"),
        FieldSpec("group", Ints(), doc="constraint groups handled"),
        FieldSpec("showCellWidth", Real()),
        FieldSpec("showTranslation", Reals(3)),
        _CONSTRAINT_CORRECTIONS,
    ),
)

# GenericConstraintSolver Data (base of the Gauss-Seidel and NNCG solvers).
_GENERIC_SOLVER_FIELDS = (
    FieldSpec("maxIterations", Int(), 1000, "maximum iterations", aliases=("maxIt",), valid=MUST_BE_POSITIVE),
    FieldSpec("tolerance", Real(), 0.001, "residual threshold", valid=MUST_BE_NONNEGATIVE),
    FieldSpec("sor", Real(), 1.0, "successive over-relaxation factor (0-2)"),
    FieldSpec("regularizationTerm", Real(), 0.0, "added to the compliance diagonal"),
    FieldSpec("scaleTolerance", Bool(), True, "scale the tolerance with the number of constraints"),
    FieldSpec("allVerified", Bool(), False, "every constraint must meet the tolerance"),
    FieldSpec("computeGraphs", Bool(), False),
    FieldSpec("computeConstraintForces", Bool(), False),
    FieldSpec("constraintForces", Reals(), doc="output: constraint forces"),
    _CONSTRAINT_CORRECTIONS,
)
_BUILT_SOLVER_FIELDS = (
    FieldSpec("multithreading", Bool(), False, "build compliances concurrently"),
    FieldSpec("useSVDForRegularization", Bool(), False),
    FieldSpec("svdSingularValueNullSpaceCriteriaFactor", Real(), 0.01),
    FieldSpec("svdSingularVectorNullSpaceCriteriaFactor", Real(), 0.001),
    *_GENERIC_SOLVER_FIELDS,
)

BLOCK_GAUSS_SEIDEL_CONSTRAINT_SOLVER = ComponentSpec(
    name="BlockGaussSeidelConstraintSolver",
    category=Category.CONSTRAINT_SOLVER,
    module=_SOLVER_MODULE,
    doc="Projected block Gauss-Seidel on the assembled constraint compliance.",
    former_names=("GenericConstraintSolver",),
    supported=True,
    lowering="constraint_solver",
    variant=Variant.BLOCK_GAUSS_SEIDEL,
    effects=_SOLVE,
    fields=_BUILT_SOLVER_FIELDS,
)

NNCG_CONSTRAINT_SOLVER = ComponentSpec(
    name="NNCGConstraintSolver",
    category=Category.CONSTRAINT_SOLVER,
    module=_SOLVER_MODULE,
    doc="Non-smooth non-linear conjugate gradient constraint solver.",
    supported=True,
    lowering="constraint_solver",
    variant=Variant.NNCG,
    effects=_SOLVE,
    fields=_BUILT_SOLVER_FIELDS,
)

UNBUILT_GAUSS_SEIDEL_CONSTRAINT_SOLVER = ComponentSpec(
    name="UnbuiltGaussSeidelConstraintSolver",
    category=Category.CONSTRAINT_SOLVER,
    module=_SOLVER_MODULE,
    doc="Gauss-Seidel constraint solver without assembling the compliance matrix.",
    supported=True,
    lowering="constraint_solver",
    variant=Variant.UNBUILT_GAUSS_SEIDEL,
    effects=_SOLVE,
    fields=_GENERIC_SOLVER_FIELDS,
)

_CORRECTION_TYPES = ("Vec3d", "Vec2d", "Vec1d", "Rigid3d")
_CONSTRAINT_SOLVERS = FieldSpec("constraintSolvers", LinkList("constraint_solver"), doc="solvers using it")

LINEAR_SOLVER_CONSTRAINT_CORRECTION = ComponentSpec(
    name="LinearSolverConstraintCorrection",
    category=Category.CONSTRAINT_CORRECTION,
    module=_CORRECTION_MODULE,
    doc="Constraint compliance computed with the object's linear solver (exact, costly).",
    templates=_CORRECTION_TYPES,
    default_template="Vec3d",
    supported=True,
    lowering="constraint_correction",
    variant=Variant.LINEAR_SOLVER,
    effects=_SOLVE,
    fields=(
        FieldSpec("wire_optimization", Bool(), False, "reorder constraints along a wire-like topology"),
        FieldSpec("regularizationTerm", Real(), 0.0, "added to the compliance diagonal"),
        FieldSpec("linearSolver", Link("linear_solver"), doc="linear solver (default: found in context)"),
        FieldSpec("ODESolver", Link("ode_solver"), doc="ODE solver (default: found in context)"),
        _CONSTRAINT_SOLVERS,
        MSTATE_LINK,
    ),
)

UNCOUPLED_CONSTRAINT_CORRECTION = ComponentSpec(
    name="UncoupledConstraintCorrection",
    category=Category.CONSTRAINT_CORRECTION,
    module=_CORRECTION_MODULE,
    doc="Diagonal (per-DOF) constraint compliance approximation.",
    templates=("Vec1d", "Vec2d", "Vec3d", "Rigid3d"),
    default_template="Vec1d",
    supported=True,
    lowering="constraint_correction",
    variant=Variant.UNCOUPLED,
    effects=_SOLVE,
    fields=(
        FieldSpec("compliance", Reals(), doc="compliance per DOF (Rigid3d: 7 values)"),
        FieldSpec(
            "defaultCompliance", Real(), 0.00001, "compliance when none is given", valid=MUST_BE_NONNEGATIVE
        ),
        FieldSpec("verbose", Bool(), False),
        FieldSpec("correctionVelocityFactor", Real(), 1.0),
        FieldSpec("correctionPositionFactor", Real(), 1.0),
        FieldSpec(
            "useOdeSolverIntegrationFactors", Bool(), True, "take the correction factors from the ODE solver"
        ),
        _CONSTRAINT_SOLVERS,
        MSTATE_LINK,
        TOPOLOGY_LINK,
    ),
)

BILATERAL_LAGRANGIAN_CONSTRAINT = ComponentSpec(
    name="BilateralLagrangianConstraint",
    category=Category.LAGRANGIAN_CONSTRAINT,
    module="Sofa.Component.Constraint.Lagrangian.Model",
    doc="Holonomic attachment of points of object1 to points of object2.",
    templates=("Vec3d", "Rigid3d"),
    default_template="Vec3d",
    renamed_from=("BilateralInteractionConstraint",),
    supported=True,
    lowering="bilateral_constraint",
    effects=_SOLVE,
    fields=(
        FieldSpec("first_point", Ints(), doc="constrained DOFs of object1", indexes="object1"),
        FieldSpec("second_point", Ints(), doc="constrained DOFs of object2", indexes="object2"),
        FieldSpec("rest_vector", Coords(deriv=True), doc="relative offsets to keep (optional)"),
        FieldSpec("activate", Bool(), True),
        FieldSpec("keepOrientationDifference", Bool(), False, "rigids: keep the initial relative rotation"),
        FieldSpec("load", Real(), 1.0, "factor on the constraint force (incremental loading)"),
        FieldSpec("endTime", Real(), -1.0, "time after which the constraint stops (negative: never)"),
        FieldSpec("topology1", Link("topology")),
        FieldSpec("topology2", Link("topology")),
        *PAIR_LINKS,
    ),
)

_MODEL_MODULE = "Sofa.Component.Constraint.Lagrangian.Model"

FIXED_LAGRANGIAN_CONSTRAINT = ComponentSpec(
    name="FixedLagrangianConstraint",
    category=Category.LAGRANGIAN_CONSTRAINT,
    module=_MODEL_MODULE,
    doc="Holds DOFs at their rest position by bilateral constraint rows (one per coordinate).",
    templates=("Vec3d", "Vec2d", "Vec1d", "Vec6d", "Rigid3d"),
    default_template="Vec3d",
    supported=True,
    lowering="fixed_lagrangian_constraint",
    effects=_SOLVE,
    fields=(
        FieldSpec("indices", Ints(), doc="DOFs to fix", indexes="state"),
        FieldSpec("fixAll", Bool(), False, "fix every DOF"),
        FieldSpec("endTime", Real(), -1.0, "time after which the constraint stops (negative: never)"),
        MSTATE_LINK,
    ),
)

SLIDING_LAGRANGIAN_CONSTRAINT = ComponentSpec(
    name="SlidingLagrangianConstraint",
    category=Category.LAGRANGIAN_CONSTRAINT,
    module=_MODEL_MODULE,
    doc="A point of object1 slides along a segment of object2.",
    templates=("Vec3d", "Rigid3d"),
    default_template="Vec3d",
    renamed_from=("SlidingConstraint",),
    supported=True,
    lowering="sliding_constraint",
    effects=_SOLVE,
    fields=(
        FieldSpec("sliding_point", Int(nonnegative=True), 0, "sliding point in object1", indexes="object1"),
        FieldSpec("axis_1", Int(nonnegative=True), 0, "first end of the axis in object2", indexes="object2"),
        FieldSpec("axis_2", Int(nonnegative=True), 0, "second end of the axis in object2", indexes="object2"),
        FieldSpec("force", Reals(), doc="output: constraint impulse"),
        FieldSpec("endTime", Real(), -1.0),
        *PAIR_LINKS,
    ),
)

STOPPER_LAGRANGIAN_CONSTRAINT = ComponentSpec(
    name="StopperLagrangianConstraint",
    category=Category.LAGRANGIAN_CONSTRAINT,
    module=_MODEL_MODULE,
    doc="Keeps one scalar DOF between min and max.",
    templates=("Vec1d",),
    default_template="Vec1d",
    renamed_from=("StopperConstraint",),
    supported=True,
    lowering="stopper_constraint",
    effects=_SOLVE,
    fields=(
        FieldSpec("index", Int(nonnegative=True), 0, "constrained DOF", indexes="state"),
        FieldSpec("min", Real(), -100.0),
        FieldSpec("max", Real(), 100.0),
        FieldSpec("endTime", Real(), -1.0),
        MSTATE_LINK,
    ),
)

UNIFORM_LAGRANGIAN_CONSTRAINT = ComponentSpec(
    name="UniformLagrangianConstraint",
    category=Category.LAGRANGIAN_CONSTRAINT,
    module=_MODEL_MODULE,
    doc="One bilateral constraint per scalar DOF (to zero or to the rest position).",
    templates=("Vec1d",),
    default_template="Vec1d",
    renamed_from=("UniformConstraint",),
    supported=True,
    lowering="uniform_constraint",
    effects=_SOLVE,
    fields=(
        FieldSpec("iterative", Bool(), True, "iterate over the constraints (else block factorisation)"),
        FieldSpec("constrainToRestPos", Bool(), False),
        FieldSpec("endTime", Real(), -1.0),
        MSTATE_LINK,
    ),
)

UNILATERAL_LAGRANGIAN_CONSTRAINT = ComponentSpec(
    name="UnilateralLagrangianConstraint",
    category=Category.LAGRANGIAN_CONSTRAINT,
    module=_MODEL_MODULE,
    doc="Unilateral (contact) constraints with friction between two states.",
    templates=("Vec3d",),
    default_template="Vec3d",
    renamed_from=("UnilateralInteractionConstraint",),
    unsupported_reason=_REASON,
    effects=_SOLVE,
    fields=(FieldSpec("endTime", Real(), -1.0), *PAIR_LINKS),
)

COMPONENTS = (
    FREE_MOTION_ANIMATION_LOOP,
    LCP_CONSTRAINT_SOLVER,
    BLOCK_GAUSS_SEIDEL_CONSTRAINT_SOLVER,
    NNCG_CONSTRAINT_SOLVER,
    UNBUILT_GAUSS_SEIDEL_CONSTRAINT_SOLVER,
    LINEAR_SOLVER_CONSTRAINT_CORRECTION,
    UNCOUPLED_CONSTRAINT_CORRECTION,
    BILATERAL_LAGRANGIAN_CONSTRAINT,
    FIXED_LAGRANGIAN_CONSTRAINT,
    SLIDING_LAGRANGIAN_CONSTRAINT,
    STOPPER_LAGRANGIAN_CONSTRAINT,
    UNIFORM_LAGRANGIAN_CONSTRAINT,
    UNILATERAL_LAGRANGIAN_CONSTRAINT,
)
