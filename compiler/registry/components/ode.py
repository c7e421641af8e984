"""ODE solvers (time integrators) and the Newton-Raphson helper of StaticSolver."""

from __future__ import annotations

from ..fields import Bool, Enum, FileName, Int, Link, Real
from ..spec import Category, ComponentSpec, Effect, FieldSpec
from .common import MUST_BE_AT_LEAST_ONE, MUST_BE_NONNEGATIVE, MUST_BE_POSITIVE

_BACKWARD = "Sofa.Component.ODESolver.Backward"
_FORWARD = "Sofa.Component.ODESolver.Forward"
_INTEGRATION = frozenset({Effect.INTEGRATION})

_LINEAR_SOLVER = FieldSpec("linearSolver", Link("linear_solver"), doc="linear solver (default: found below)")
_THREAD_SAFE = FieldSpec("threadSafeVisitor", Bool(), False, "avoid visitor reallocation (thread safety)")


def _rayleigh(what: str) -> tuple[FieldSpec, FieldSpec]:
    return (
        FieldSpec(
            "rayleighStiffness",
            Real(),
            0.0,
            f"Rayleigh damping coefficient on the stiffness ({what})",
            valid=MUST_BE_NONNEGATIVE,
        ),
        FieldSpec(
            "rayleighMass",
            Real(),
            0.0,
            f"Rayleigh damping coefficient on the mass ({what})",
            valid=MUST_BE_NONNEGATIVE,
        ),
    )


_VDAMPING = FieldSpec(
    "vdamping", Real(), 0.0, "velocity decay rate: v *= exp(-dt vdamping)", valid=MUST_BE_NONNEGATIVE
)

EULER_IMPLICIT_SOLVER = ComponentSpec(
    name="EulerImplicitSolver",
    lowering="euler_implicit",
    category=Category.ODE_SOLVER,
    module=_BACKWARD,
    doc="Linearised backward Euler (one linear solve per step, no Newton iterations).",
    former_names=("EulerImplicit", "ImplicitEulerSolver", "ImplicitEuler"),
    supported=True,
    needs_linear_solver=True,
    effects=_INTEGRATION,
    fields=(
        *_rayleigh("r_K"),
        _VDAMPING,
        FieldSpec("firstOrder", Bool(), False, "first-order system: (M - h K) v = f, x += h v"),
        FieldSpec("trapezoidalScheme", Bool(), False, "trapezoidal rule instead of backward Euler"),
        FieldSpec("solveConstraint", Bool(), False, "apply a constraint solver after the solve"),
        FieldSpec("computeResidual", Bool(), False, "compute the residual after the solve"),
        FieldSpec("residual", Real(), doc="output: residual norm"),
        _THREAD_SAFE,
        _LINEAR_SOLVER,
    ),
)

EULER_EXPLICIT_SOLVER = ComponentSpec(
    name="EulerExplicitSolver",
    lowering="euler_explicit",
    category=Category.ODE_SOLVER,
    module=_FORWARD,
    doc="Explicit Euler, symplectic (v first, then x with the new v) by default. Needs a linear solver "
    "only when some mass is not diagonal.",
    former_names=("EulerSolver", "Euler", "EulerExplicit", "ExplicitEuler", "ExplicitEulerSolver"),
    supported=True,
    effects=_INTEGRATION,
    fields=(
        FieldSpec("symplectic", Bool(), True, "update velocities before positions (semi-implicit Euler)"),
        _THREAD_SAFE,
        _LINEAR_SOLVER,
    ),
)

RUNGE_KUTTA2_SOLVER = ComponentSpec(
    name="RungeKutta2Solver",
    lowering="runge_kutta2",
    category=Category.ODE_SOLVER,
    module=_FORWARD,
    doc="Explicit midpoint method on (x, v).",
    former_names=("RungeKutta2",),
    supported=True,
    effects=_INTEGRATION,
)

RUNGE_KUTTA4_SOLVER = ComponentSpec(
    name="RungeKutta4Solver",
    lowering="runge_kutta4",
    category=Category.ODE_SOLVER,
    module=_FORWARD,
    doc="Classical explicit 4-stage Runge-Kutta on (x, v).",
    former_names=("RungeKutta4",),
    supported=True,
    effects=_INTEGRATION,
)

NEWMARK_IMPLICIT_SOLVER = ComponentSpec(
    name="NewmarkImplicitSolver",
    lowering="newmark",
    category=Category.ODE_SOLVER,
    module=_BACKWARD,
    doc="Implicit Newmark-beta scheme with Rayleigh damping (gamma 1/2, beta 1/4: average acceleration).",
    supported=True,
    needs_linear_solver=True,
    effects=_INTEGRATION,
    fields=(
        *_rayleigh("C = rM M + rK K"),
        _VDAMPING,
        FieldSpec("gamma", Real(), 0.5, "Newmark gamma", valid=MUST_BE_NONNEGATIVE),
        FieldSpec("beta", Real(), 0.25, "Newmark beta", valid=MUST_BE_NONNEGATIVE),
        _THREAD_SAFE,
        _LINEAR_SOLVER,
    ),
)

# StaticSolver attributes from before the Newton parameters moved to NewtonRaphsonSolver: still read
# (with a warning) and forwarded to an auto-created NewtonRaphsonSolver.
_STATIC_LEGACY = (
    FieldSpec(
        "newton_iterations",
        Int(),
        doc="legacy: use NewtonRaphsonSolver.maxNbIterationsNewton",
        deprecated=True,
        valid=MUST_BE_AT_LEAST_ONE,
    ),
    FieldSpec(
        "absolute_correction_tolerance_threshold",
        Real(),
        deprecated=True,
        doc="legacy: use NewtonRaphsonSolver.absoluteEstimateDifferenceThreshold",
    ),
    FieldSpec(
        "relative_correction_tolerance_threshold",
        Real(),
        deprecated=True,
        doc="legacy: use NewtonRaphsonSolver.relativeEstimateDifferenceThreshold",
    ),
    FieldSpec(
        "absolute_residual_tolerance_threshold",
        Real(),
        deprecated=True,
        doc="legacy: use NewtonRaphsonSolver.absoluteResidualStoppingThreshold",
    ),
    FieldSpec(
        "relative_residual_tolerance_threshold",
        Real(),
        deprecated=True,
        doc="legacy: forwarded to NewtonRaphsonSolver.relativeEstimateDifferenceThreshold",
    ),
)

STATIC_SOLVER = ComponentSpec(
    name="StaticSolver",
    lowering="static",
    category=Category.ODE_SOLVER,
    module=_BACKWARD,
    doc="Static equilibrium f(x) = 0 by Newton-Raphson (a NewtonRaphsonSolver found below, or created).",
    supported=True,
    needs_linear_solver=True,
    effects=_INTEGRATION,
    fields=(
        FieldSpec(
            "newtonSolver", Link("newton_solver"), doc="Newton-Raphson solver (default: found or created)"
        ),
        *_STATIC_LEGACY,
        _LINEAR_SOLVER,
    ),
)

NEWTON_RAPHSON_SOLVER = ComponentSpec(
    name="NewtonRaphsonSolver",
    category=Category.UTILITY,
    module=_BACKWARD,
    doc="Newton-Raphson iterations used by StaticSolver (created with defaults when absent).",
    supported=True,
    effects=_INTEGRATION,
    fields=(
        FieldSpec("maxNbIterationsNewton", Int(), 1, "maximum Newton iterations", valid=MUST_BE_AT_LEAST_ONE),
        FieldSpec(
            "absoluteResidualStoppingThreshold",
            Real(),
            1e-5,
            "stop when |f| is below this",
            valid=MUST_BE_NONNEGATIVE,
        ),
        FieldSpec(
            "relativeInitialStoppingThreshold",
            Real(),
            1e-5,
            "stop when |f| / |f0| is below this",
            valid=MUST_BE_NONNEGATIVE,
        ),
        FieldSpec(
            "relativeSuccessiveStoppingThreshold",
            Real(),
            1e-5,
            "stop when |f_k| / |f_k-1| is below this",
            valid=MUST_BE_NONNEGATIVE,
        ),
        FieldSpec(
            "absoluteEstimateDifferenceThreshold",
            Real(),
            0.0,
            "stop when |dx| is below this",
            valid=MUST_BE_NONNEGATIVE,
        ),
        FieldSpec(
            "relativeEstimateDifferenceThreshold",
            Real(),
            0.0,
            "stop when |dx| / |x| is below this",
            valid=MUST_BE_NONNEGATIVE,
        ),
        FieldSpec(
            "maxNbIterationsLineSearch",
            Int(),
            1,
            "maximum line-search iterations",
            valid=MUST_BE_AT_LEAST_ONE,
        ),
        FieldSpec(
            "lineSearchCoefficient",
            Real(),
            0.5,
            "step reduction factor of the line search",
            valid=MUST_BE_POSITIVE,
        ),
        FieldSpec("updateStateWhenDiverged", Bool(), True, "keep the last iterate even if diverging"),
        FieldSpec("warnWhenLineSearchFails", Bool(), True),
        FieldSpec("warnWhenDiverge", Bool(), True),
        FieldSpec(
            "status",
            Enum(
                values=(
                    "Undefined",
                    "Running",
                    "ConvergedEquilibrium",
                    "DivergedLineSearch",
                    "DivergedMaxIterations",
                    "ConvergedResidualSuccessiveRatio",
                    "ConvergedResidualInitialRatio",
                    "ConvergedAbsoluteResidual",
                    "ConvergedRelativeEstimateDifference",
                    "ConvergedAbsoluteEstimateDifference",
                )
            ),
            doc="output: convergence status",
        ),
        _LINEAR_SOLVER,
    ),
)

VARIATIONAL_SYMPLECTIC_SOLVER = ComponentSpec(
    name="VariationalSymplecticSolver",
    lowering="variational",
    category=Category.ODE_SOLVER,
    module=_BACKWARD,
    doc="Variational (implicit midpoint) integrator of Kharevych et al. 2006, conserving momentum and "
    "energy: Newton iterations on the midpoint displacement, with momentum carried between steps.",
    former_names=("VariationalSolver",),
    supported=True,
    needs_linear_solver=True,
    effects=_INTEGRATION,
    fields=(
        FieldSpec(
            "newtonError",
            Real(),
            0.01,
            "Newton tolerance on |x_i - x_i-1| / |x_k|",
            valid=MUST_BE_NONNEGATIVE,
        ),
        FieldSpec("steps", Int(), 5, "maximum Newton steps", valid=MUST_BE_AT_LEAST_ONE),
        *_rayleigh("r_K"),
        FieldSpec("saveEnergyInFile", Bool(), False, "write the energies to the CSV `file` each step"),
        FieldSpec("explicitIntegration", Bool(), False, "explicit variant (not compiled by sofac)"),
        FieldSpec("file", FileName(output=True), doc="output CSV file of the energies"),
        FieldSpec("computeHamiltonian", Bool(), True, "compute hamiltonianEnergy each step (one more solve)"),
        FieldSpec("hamiltonianEnergy", Real(), 0.0, "output: Hamiltonian"),
        FieldSpec(
            "useIncrementalPotentialEnergy",
            Bool(),
            True,
            "potential energy summed from the work of the forces (else the force fields' own)",
        ),
        _THREAD_SAFE,
        _LINEAR_SOLVER,
    ),
)

CENTRAL_DIFFERENCE_SOLVER = ComponentSpec(
    name="CentralDifferenceSolver",
    lowering="central_difference",
    category=Category.ODE_SOLVER,
    module=_FORWARD,
    doc="Explicit central difference (leapfrog): a = M^-1 f, v += h a, x += h v; with rayleighMass r, "
    "v = ((1/h - r/2) v + a) / (1/h + r/2). Diagonal masses only (SOFA's accFromF).",
    supported=True,
    effects=_INTEGRATION,
    fields=(
        FieldSpec("rayleighMass", Real(), 0.0, "Rayleigh damping coefficient on the mass"),
        _THREAD_SAFE,
    ),
)

BDF_ODE_SOLVER = ComponentSpec(
    name="BDFOdeSolver",
    lowering="bdf",
    category=Category.ODE_SOLVER,
    module=_BACKWARD,
    doc="Backward differentiation formula of order `order` (lower while too few steps are done), "
    "solved by a NewtonRaphsonSolver in its node or below (SOFA's velocity-based residual).",
    supported=True,
    needs_linear_solver=True,
    effects=_INTEGRATION,
    fields=(
        FieldSpec("order", Int(nonnegative=True), 1, "order of the method (0 is taken as 1)"),
        *_rayleigh("C = rM M + rK K"),
        FieldSpec("newtonSolver", Link("newton_solver"), doc="Newton-Raphson solver (default: found below)"),
        _LINEAR_SOLVER,
    ),
)

COMPONENTS = (
    CENTRAL_DIFFERENCE_SOLVER,
    BDF_ODE_SOLVER,
    EULER_IMPLICIT_SOLVER,
    EULER_EXPLICIT_SOLVER,
    RUNGE_KUTTA2_SOLVER,
    RUNGE_KUTTA4_SOLVER,
    NEWMARK_IMPLICIT_SOLVER,
    STATIC_SOLVER,
    NEWTON_RAPHSON_SOLVER,
    VARIATIONAL_SYMPLECTIC_SOLVER,
)
