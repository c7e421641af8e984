"""Linear solvers, preconditioners, linear systems and orderings (the A x = b of implicit steps)."""

from __future__ import annotations

from ..fields import Bool, Int, IntVector, Link, LinkList, Real
from ..spec import Category, ComponentSpec, Effect, FieldSpec, Variant
from .common import (
    CRS_BLOCKS,
    CRS_MAT3,
    CRS_SCALAR,
    GRAPH_SCATTERED,
    LINEAR_SOLVER_FIELDS,
    MUST_BE_AT_LEAST_ONE,
    MUST_BE_NONNEGATIVE,
    MUST_BE_POSITIVE,
)

_ITERATIVE = "Sofa.Component.LinearSolver.Iterative"
_DIRECT = "Sofa.Component.LinearSolver.Direct"
_PRECONDITIONER = "Sofa.Component.LinearSolver.Preconditioner"
_SYSTEM = "Sofa.Component.LinearSystem"
_SOLVE = frozenset({Effect.LINEAR_SOLVE})

FULL_MATRIX = "FullMatrix"
SPARSE_MATRIX = "SparseMatrix"
DIAGONAL_MATRIX = "DiagonalMatrix"
BLOCK_DIAGONAL_MATRIX = "BlockDiagonalMatrixMat3x3d"
ROTATION_MATRIX = "RotationMatrixd"
BTD_MATRIX = "BTDMatrix6d"

# Iterative solvers: matrix-free (default) or on an assembled matrix.
_ITERATIVE_TEMPLATES = (GRAPH_SCATTERED, FULL_MATRIX, SPARSE_MATRIX, CRS_SCALAR, *CRS_BLOCKS)
_SPARSE_DIRECT_TEMPLATES = (CRS_SCALAR, CRS_MAT3)

_ITERATIONS = FieldSpec("iterations", Int(), 25, "maximum iterations", valid=MUST_BE_AT_LEAST_ONE)
_TOLERANCE = FieldSpec(
    "tolerance", Real(), 1e-5, "stop when |r|^2 / |b|^2 is below this", valid=MUST_BE_NONNEGATIVE
)
_ORDERING = FieldSpec(
    "orderingMethod", Link("ordering"), doc="fill-reducing ordering (default: found or created)"
)
_VERBOSE_LOG = FieldSpec("verbose", Bool(), doc="alias of printLog", sets=("printLog",))

CG_LINEAR_SOLVER = ComponentSpec(
    name="CGLinearSolver",
    lowering="cg",
    category=Category.LINEAR_SOLVER,
    module=_ITERATIVE,
    doc="Unpreconditioned conjugate gradient; matrix-free with GraphScattered (default).",
    templates=_ITERATIVE_TEMPLATES,
    default_template=GRAPH_SCATTERED,
    former_names=("CGSolver", "ConjugateGradient"),
    supported=True,
    effects=_SOLVE,
    fields=(
        _ITERATIONS,
        _TOLERANCE,
        FieldSpec(
            "threshold",
            Real(),
            1e-5,
            "stop when the denominator p^T A p falls below this",
            valid=MUST_BE_NONNEGATIVE,
        ),
        FieldSpec("warmStart", Bool(), False, "start from the previous solution instead of 0"),
        *LINEAR_SOLVER_FIELDS,
    ),
)

PCG_LINEAR_SOLVER = ComponentSpec(
    name="PCGLinearSolver",
    lowering="pcg",
    category=Category.LINEAR_SOLVER,
    module=_ITERATIVE,
    doc="Preconditioned conjugate gradient (matrix-free), preconditioned by another linear solver.",
    templates=(GRAPH_SCATTERED,),
    default_template=GRAPH_SCATTERED,
    renamed_from=("ShewchukPCGLinearSolver",),
    supported=True,
    effects=_SOLVE,
    fields=(
        _ITERATIONS,
        _TOLERANCE,
        FieldSpec("use_precond", Bool(), True, "apply the preconditioner"),
        FieldSpec("preconditioner", Link("linear_solver"), doc="linear solver used as preconditioner"),
        FieldSpec(
            "update_step",
            Int(),
            1,
            "deprecated in SOFA (a DeprecatedData: warned about, then ignored); the preconditioner's "
            "refresh period is its PreconditionedMatrixFreeSystem's assemblingRate",
            deprecated=True,
        ),
        *LINEAR_SOLVER_FIELDS,
    ),
)

MIN_RES_LINEAR_SOLVER = ComponentSpec(
    name="MinResLinearSolver",
    lowering="minres",
    category=Category.LINEAR_SOLVER,
    module=_ITERATIVE,
    doc="MINRES iterations (symmetric, possibly indefinite systems).",
    templates=_ITERATIVE_TEMPLATES,
    default_template=GRAPH_SCATTERED,
    former_names=("MINRESSolver", "MinResSolver"),
    supported=True,
    effects=_SOLVE,
    fields=(_ITERATIONS, _TOLERANCE, *LINEAR_SOLVER_FIELDS),
)

SPARSE_LDL_SOLVER = ComponentSpec(
    name="SparseLDLSolver",
    lowering="direct",
    category=Category.LINEAR_SOLVER,
    module=_DIRECT,
    doc="Direct sparse L D L^T factorisation of the assembled matrix, every step.",
    templates=_SPARSE_DIRECT_TEMPLATES,
    default_template=CRS_SCALAR,
    supported=True,
    effects=_SOLVE,
    fields=(
        FieldSpec("precomputeSymbolicDecomposition", Bool(), True, "reuse the symbolic factorisation"),
        FieldSpec("L_nnz", Int(), 0, "output: non-zeros of L"),
        _ORDERING,
        *LINEAR_SOLVER_FIELDS,
    ),
)

SPARSE_CHOLESKY_SOLVER = ComponentSpec(
    name="SparseCholeskySolver",
    lowering="direct",
    variant=Variant.LLT,  # factors L L^T (CHOLMOD's L L^T), where SparseLDLSolver factors L D L^T
    category=Category.LINEAR_SOLVER,
    module="CSparseSolvers",
    doc="Direct sparse Cholesky (L L^T) factorisation. Moved out of SOFA's main repository into the "
    'CSparseSolvers plugin in v23.12 (recent SOFA needs <RequiredPlugin name="CSparseSolvers"/>).',
    templates=(CRS_SCALAR,),
    default_template=CRS_SCALAR,
    supported=True,
    effects=_SOLVE,
    fields=(_ORDERING, *LINEAR_SOLVER_FIELDS),
)


SPARSE_LU_SOLVER = ComponentSpec(
    name="SparseLUSolver",
    lowering="direct",
    category=Category.LINEAR_SOLVER,
    module="CSparseSolvers",
    doc="Direct sparse LU factorisation (CSparse). Moved out of SOFA's main repository into the "
    "CSparseSolvers plugin in v23.12. The implicit system matrix is symmetric, so sofac solves it "
    "with the same sparse factorisation as SparseLDLSolver (the same solution, to round-off).",
    templates=(CRS_SCALAR,),
    default_template=CRS_SCALAR,
    supported=True,
    effects=_SOLVE,
    fields=(
        FieldSpec("tolerance", Real(), 0.001, "tolerance of the factorisation (CSparse's pivoting)"),
        _ORDERING,
        *LINEAR_SOLVER_FIELDS,
    ),
)


def _eigen(name: str, what: str, variant: Variant | None = None) -> ComponentSpec:
    return ComponentSpec(
        name=name,
        lowering="direct",
        variant=variant,
        category=Category.LINEAR_SOLVER,
        module=_DIRECT,
        doc=f"Direct sparse {what} factorisation (Eigen) of the assembled matrix.",
        templates=_SPARSE_DIRECT_TEMPLATES,
        default_template=CRS_SCALAR,
        supported=True,
        effects=_SOLVE,
        fields=(_ORDERING, *LINEAR_SOLVER_FIELDS),
    )


ASYNC_SPARSE_LDL_SOLVER = ComponentSpec(
    name="AsyncSparseLDLSolver",
    lowering="direct",
    category=Category.LINEAR_SOLVER,
    module=_DIRECT,
    doc="SparseLDLSolver whose factorisation runs in a thread while the step goes on. With the "
    "animation loops sofac compiles (no constraint correction asks for an early solve) it solves "
    "every step with the current matrix, as SparseLDLSolver: the same results.",
    templates=_SPARSE_DIRECT_TEMPLATES,
    default_template=CRS_SCALAR,
    supported=True,
    effects=_SOLVE,
    fields=(
        FieldSpec("precomputeSymbolicDecomposition", Bool(), True, "reuse the symbolic factorisation"),
        FieldSpec("L_nnz", Int(), 0, "output: non-zeros of L"),
        FieldSpec("enableAssembly", Bool(), True, "assemble the system (else reuse the last factor)"),
        _ORDERING,
        *LINEAR_SOLVER_FIELDS,
    ),
)

CHOLESKY_SOLVER = ComponentSpec(
    name="CholeskySolver",
    lowering="direct",
    variant=Variant.LLT,
    category=Category.LINEAR_SOLVER,
    module=_DIRECT,
    doc="Dense Cholesky (L L^T) factorisation of the system matrix; sofac factors the same matrix "
    "sparse (CHOLMOD's L L^T): the same solution, to round-off.",
    templates=(SPARSE_MATRIX, FULL_MATRIX, "SparseMatrixd", "FullMatrixd", "NewMatSymmetricMatrix"),
    default_template=SPARSE_MATRIX,
    supported=True,
    effects=_SOLVE,
    fields=(*LINEAR_SOLVER_FIELDS,),
)

LU_LINEAR_SOLVER = ComponentSpec(
    name="LULinearSolver",
    lowering="direct",
    category=Category.LINEAR_SOLVER,
    module="SofaNewmat",
    doc="Dense LU factorisation (SofaNewmat plugin). The implicit system matrix is symmetric, so "
    "sofac solves it with SparseLDLSolver's factorisation: the same solution, to round-off.",
    templates=("NewMatMatrix", "NewMatSymmetricMatrix", "NewMatBandMatrix", "NewMatSymmetricBandMatrix"),
    default_template="NewMatMatrix",
    supported=True,
    effects=_SOLVE,
    fields=(_VERBOSE_LOG, *LINEAR_SOLVER_FIELDS),
)

EIGEN_CHOLMOD_SUPERNODAL_LLT = ComponentSpec(
    name="EigenCholmodSupernodalLLT",
    lowering="direct",
    variant=Variant.LLT,
    category=Category.LINEAR_SOLVER,
    module="SofaCHOLMOD",
    doc="CHOLMOD's supernodal L L^T (SofaCHOLMOD plugin): sofac's direct solvers factor L L^T with "
    "CHOLMOD's analysis and supernodal kernel.",
    templates=_SPARSE_DIRECT_TEMPLATES,
    default_template=CRS_SCALAR,
    supported=True,
    effects=_SOLVE,
    fields=(
        FieldSpec("numThreads", Int(), 1, "CHOLMOD's threads (sofac's kernel runs on one)"),
        _ORDERING,
        *LINEAR_SOLVER_FIELDS,
    ),
)

EIGEN_SIMPLICIAL_LDLT = _eigen("EigenSimplicialLDLT", "L D L^T")
EIGEN_SIMPLICIAL_LLT = _eigen("EigenSimplicialLLT", "Cholesky L L^T", variant=Variant.LLT)
EIGEN_SPARSE_LU = _eigen("EigenSparseLU", "LU")
EIGEN_SPARSE_QR = _eigen("EigenSparseQR", "QR")

BTD_LINEAR_SOLVER = ComponentSpec(
    name="BTDLinearSolver",
    category=Category.LINEAR_SOLVER,
    module=_DIRECT,
    doc="Thomas algorithm on a block-tridiagonal matrix (6x6 blocks, beams).",
    templates=(BTD_MATRIX,),
    default_template=BTD_MATRIX,
    lowering="btd",
    supported=True,
    effects=_SOLVE,
    fields=(
        FieldSpec("verbose", Bool(), False, "dump the system every iteration"),
        FieldSpec("showProblem", Bool(), False),
        FieldSpec("subpartSolve", Bool(), False, "solve only a subpart of the system"),
        FieldSpec("verification", Bool(), False),
        *LINEAR_SOLVER_FIELDS,
    ),
)

SVD_LINEAR_SOLVER = ComponentSpec(
    name="SVDLinearSolver",
    category=Category.LINEAR_SOLVER,
    module=_DIRECT,
    doc="Dense SVD of the assembled, projected system matrix (Eigen's JacobiSVD, as SOFA's); "
    "singular values at or below minSingularValue are treated as 0 (a pseudo-inverse).",
    templates=(FULL_MATRIX, "FullMatrixd", CRS_SCALAR, CRS_MAT3),
    default_template=FULL_MATRIX,
    former_names=("SVDLinear", "SVD"),
    lowering="direct",
    variant=Variant.SVD,
    supported=True,
    effects=_SOLVE,
    fields=(
        FieldSpec("verbose", Bool(), False),
        FieldSpec(
            "minSingularValue",
            Real(),
            1e-6,
            "singular values below this are set to 0",
            valid=MUST_BE_NONNEGATIVE,
        ),
        FieldSpec("conditionNumber", Real(), 0.0, "output: condition number"),
        *LINEAR_SOLVER_FIELDS,
    ),
)

PRECOMPUTED_LINEAR_SOLVER = ComponentSpec(
    name="PrecomputedLinearSolver",
    lowering="precomputed",
    category=Category.LINEAR_SOLVER,
    module=_DIRECT,
    doc="Solves with the system matrix of the first step, factorised once (SOFA precomputes its "
    "inverse then, optionally cached in a file): later changes of the matrix are ignored.",
    templates=(CRS_SCALAR,),
    default_template=CRS_SCALAR,
    supported=True,
    effects=_SOLVE,
    fields=(
        FieldSpec("jmjt_twostep", Bool(), True),
        FieldSpec("use_file", Bool(), True, "cache the inverse in a file"),
        *LINEAR_SOLVER_FIELDS,
    ),
)

JACOBI_PRECONDITIONER = ComponentSpec(
    name="JacobiPreconditioner",
    lowering="jacobi",
    category=Category.PRECONDITIONER,
    module=_PRECONDITIONER,
    doc="Diagonal (Jacobi) preconditioner.",
    templates=(DIAGONAL_MATRIX,),
    default_template=DIAGONAL_MATRIX,
    former_names=("JacobiLinearSolver", "JacobiSolver"),
    supported=True,
    effects=_SOLVE,
    fields=LINEAR_SOLVER_FIELDS,
)

BLOCK_JACOBI_PRECONDITIONER = ComponentSpec(
    name="BlockJacobiPreconditioner",
    lowering="block_jacobi",
    category=Category.PRECONDITIONER,
    module=_PRECONDITIONER,
    doc="Block-diagonal (3x3 blocks) Jacobi preconditioner.",
    templates=(BLOCK_DIAGONAL_MATRIX,),
    default_template=BLOCK_DIAGONAL_MATRIX,
    supported=True,
    effects=_SOLVE,
    fields=(_VERBOSE_LOG, *LINEAR_SOLVER_FIELDS),
)

SSOR_PRECONDITIONER = ComponentSpec(
    name="SSORPreconditioner",
    lowering="ssor",
    category=Category.PRECONDITIONER,
    module=_PRECONDITIONER,
    doc="Symmetric successive over-relaxation preconditioner.",
    templates=_SPARSE_DIRECT_TEMPLATES,
    default_template=CRS_SCALAR,
    former_names=("SSORLinearSolver", "SSORSolver"),
    supported=True,
    effects=_SOLVE,
    fields=(
        FieldSpec("omega", Real(), 1.0, "relaxation factor (0 < omega < 2)", valid=MUST_BE_POSITIVE),
        *LINEAR_SOLVER_FIELDS,
    ),
)

WARP_PRECONDITIONER = ComponentSpec(
    name="WarpPreconditioner",
    lowering="warp",
    category=Category.PRECONDITIONER,
    module=_PRECONDITIONER,
    doc="Wraps another (precomputed) solver with per-node rotations.",
    templates=(ROTATION_MATRIX,),
    default_template=ROTATION_MATRIX,
    supported=True,
    effects=_SOLVE,
    fields=(FieldSpec("linearSolver", Link("linear_solver"), doc="wrapped solver"), *LINEAR_SOLVER_FIELDS),
)

PRECOMPUTED_WARP_PRECONDITIONER = ComponentSpec(
    name="PrecomputedWarpPreconditioner",
    lowering="precomputed_warp",
    category=Category.PRECONDITIONER,
    module=_PRECONDITIONER,
    doc="Meant as a precomputed inverse rotated per node each step; SOFA sizes that inverse from its "
    "PrecomputedMatrixSystem, which nothing assembles (0x0): applied, it leaves its output vector as "
    "it was (compiled as a PCG preconditioner with its use_rotations left true).",
    templates=("Vec3d",),
    default_template="Vec3d",
    supported=True,  # as a PCGLinearSolver's preconditioner on a PrecomputedMatrixSystem, checked there
    effects=_SOLVE,
    fields=(
        FieldSpec("jmjt_twostep", Bool(), True),
        FieldSpec("use_file", Bool(), True, "cache the inverse in a file"),
        FieldSpec("share_matrix", Bool(), True),
        FieldSpec("use_rotations", Bool(), True),
        FieldSpec("draw_rotations_scale", Real(), 0.0),
        FieldSpec("linearSolver", Link("linear_solver"), doc="solver used for the precomputation"),
        *LINEAR_SOLVER_FIELDS,
    ),
)

# BaseMatrixLinearSystem + MatrixLinearSystem.
_SYSTEM_BASE = (
    FieldSpec("matrixSize", IntVector(2, nonnegative=True), doc="output: size of the global matrix"),
    FieldSpec("enableAssembly", Bool(), True, "assemble the system matrix"),
)
_MATRIX_SYSTEM_FIELDS = (
    FieldSpec("assembleStiffness", Bool(), True, "add stiffness to the global matrix"),
    FieldSpec("assembleMass", Bool(), True, "add mass to the global matrix"),
    FieldSpec("assembleDamping", Bool(), True, "add damping to the global matrix"),
    FieldSpec("assembleGeometricStiffness", Bool(), True, "add mappings' geometric stiffness"),
    FieldSpec(
        "applyProjectiveConstraints", Bool(), True, "project the matrix with the projective constraints"
    ),
    FieldSpec("applyMappedComponents", Bool(), True, "include components under mappings"),
    FieldSpec("checkIndices", Bool(), False, "check indices before adding entries (slower)"),
    FieldSpec("parallelAssemblyIndependentMatrices", Bool(), False),
    *_SYSTEM_BASE,
)

MATRIX_LINEAR_SYSTEM = ComponentSpec(
    name="MatrixLinearSystem",
    category=Category.LINEAR_SYSTEM,
    module=_SYSTEM,
    doc="Assembles the global system matrix for an assembled linear solver.",
    templates=(
        FULL_MATRIX,
        SPARSE_MATRIX,
        CRS_SCALAR,
        *CRS_BLOCKS,
        DIAGONAL_MATRIX,
        BLOCK_DIAGONAL_MATRIX,
        ROTATION_MATRIX,
    ),
    default_template=CRS_SCALAR,
    supported=True,
    effects=_SOLVE,
    fields=_MATRIX_SYSTEM_FIELDS,
)

CONSTANT_SPARSITY_PATTERN_SYSTEM = ComponentSpec(
    name="ConstantSparsityPatternSystem",
    category=Category.LINEAR_SYSTEM,
    module=_SYSTEM,
    doc="MatrixLinearSystem that reuses the sparsity pattern of the first assembly.",
    templates=(CRS_SCALAR,),
    default_template=CRS_SCALAR,
    supported=True,
    effects=_SOLVE,
    fields=_MATRIX_SYSTEM_FIELDS,
)

COMPOSITE_LINEAR_SYSTEM = ComponentSpec(
    name="CompositeLinearSystem",
    category=Category.LINEAR_SYSTEM,
    module=_SYSTEM,
    doc="Delegates to several linear systems, one of which is solved.",
    templates=(
        FULL_MATRIX,
        SPARSE_MATRIX,
        CRS_SCALAR,
        *CRS_BLOCKS,
        DIAGONAL_MATRIX,
        BLOCK_DIAGONAL_MATRIX,
        ROTATION_MATRIX,
        BTD_MATRIX,
    ),
    default_template=FULL_MATRIX,
    # The solver reads solverLinearSystem (checked where the direct solver is planned); the other
    # systems only assemble matrices for display or output, which nothing in the step reads.
    supported=True,
    effects=_SOLVE,
    fields=(
        FieldSpec("linearSystems", LinkList("linear_system"), doc="the delegated systems"),
        FieldSpec("solverLinearSystem", Link("linear_system"), doc="the system the solver uses"),
        *_SYSTEM_BASE,
    ),
)

ROTATION_MATRIX_SYSTEM = ComponentSpec(
    name="RotationMatrixSystem",
    category=Category.LINEAR_SYSTEM,
    module=_PRECONDITIONER,
    doc="Per-node rotation matrix warping another linear system (warped preconditioners).",
    templates=(ROTATION_MATRIX,),
    default_template=ROTATION_MATRIX,
    supported=True,  # with assemblingRate 1, checked where WarpPreconditioner is planned
    effects=_SOLVE,
    fields=(
        FieldSpec("assemblingRate", Int(), 1, "update period in steps", valid=MUST_BE_AT_LEAST_ONE),
        FieldSpec("mainSystem", Link("linear_system")),
        FieldSpec("rotationFinder", Link("object")),
        *_SYSTEM_BASE,
    ),
)

PRECONDITIONED_MATRIX_FREE_SYSTEM = ComponentSpec(
    name="PreconditionedMatrixFreeSystem",
    category=Category.LINEAR_SYSTEM,
    module=_ITERATIVE,
    doc="Matrix-free system whose preconditioner matrix is assembled every assemblingRate steps.",
    templates=(GRAPH_SCATTERED,),
    default_template=GRAPH_SCATTERED,
    supported=True,  # the matrix-free system of PCGLinearSolver: how sofac always works
    effects=_SOLVE,
    fields=(
        FieldSpec(
            "assemblingRate",
            Int(),
            1,
            "preconditioner update period in steps",
            aliases=("update_step",),
            valid=MUST_BE_AT_LEAST_ONE,
        ),
        FieldSpec("preconditionerSystem", Link("linear_system")),
        *_SYSTEM_BASE,
    ),
)

PRECOMPUTED_MATRIX_SYSTEM = ComponentSpec(
    name="PrecomputedMatrixSystem",
    category=Category.LINEAR_SYSTEM,
    module=_PRECONDITIONER,
    doc="PrecomputedWarpPreconditioner's system: a TypedMatrixLinearSystem that assembles nothing, so "
    "its matrix stays 0x0.",
    templates=(CRS_SCALAR,),
    default_template=CRS_SCALAR,
    supported=True,  # its only user, PrecomputedWarpPreconditioner, is checked where the PCG is planned
    effects=_SOLVE,
    fields=_SYSTEM_BASE,
)

NATURAL_ORDERING_METHOD = ComponentSpec(
    name="NaturalOrderingMethod",
    category=Category.ORDERING,
    module="Sofa.Component.LinearSolver.Ordering",
    doc="Identity permutation for sparse direct solvers (no fill-reducing reordering).",
    supported=True,
    effects=_SOLVE,
)

GLOBAL_SYSTEM_MATRIX_IMAGE = ComponentSpec(
    name="GlobalSystemMatrixImage",
    category=Category.UTILITY,
    module="SofaMatrix",
    doc="SofaMatrix plugin: shows the sparsity of the global matrix in the GUI (visual only: kept "
    "out of the step).",
    supported=True,
    effects=frozenset({Effect.VISUAL}),
    fields=(FieldSpec("linearSystem", Link("linear_system")),),
)

COMPONENTS = (
    CG_LINEAR_SOLVER,
    PCG_LINEAR_SOLVER,
    MIN_RES_LINEAR_SOLVER,
    SPARSE_LDL_SOLVER,
    SPARSE_CHOLESKY_SOLVER,
    SPARSE_LU_SOLVER,
    ASYNC_SPARSE_LDL_SOLVER,
    CHOLESKY_SOLVER,
    LU_LINEAR_SOLVER,
    EIGEN_CHOLMOD_SUPERNODAL_LLT,
    EIGEN_SIMPLICIAL_LDLT,
    EIGEN_SIMPLICIAL_LLT,
    EIGEN_SPARSE_LU,
    EIGEN_SPARSE_QR,
    BTD_LINEAR_SOLVER,
    SVD_LINEAR_SOLVER,
    PRECOMPUTED_LINEAR_SOLVER,
    JACOBI_PRECONDITIONER,
    BLOCK_JACOBI_PRECONDITIONER,
    SSOR_PRECONDITIONER,
    WARP_PRECONDITIONER,
    PRECOMPUTED_WARP_PRECONDITIONER,
    MATRIX_LINEAR_SYSTEM,
    CONSTANT_SPARSITY_PATTERN_SYSTEM,
    COMPOSITE_LINEAR_SYSTEM,
    ROTATION_MATRIX_SYSTEM,
    PRECONDITIONED_MATRIX_FREE_SYSTEM,
    PRECOMPUTED_MATRIX_SYSTEM,
    NATURAL_ORDERING_METHOD,
    GLOBAL_SYSTEM_MATRIX_IMAGE,
)
