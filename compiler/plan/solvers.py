"""What each ODE solver and linear solver makes of its group: the scheme, the solver's parameters
as buffers, and the scenes whose solver configuration is refused (E222).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from sofac import registry
from sofac.check.checker import CheckedComponent
from sofac.front.model import Component
from sofac.plan.ir import Buffer, Group, Preconditioner, Scheme
from sofac.registry import Category, Variant
from sofac.registry.components.common import GRAPH_SCATTERED
from sofac.registry.components.linear import (
    COMPOSITE_LINEAR_SYSTEM,
    PRECOMPUTED_MATRIX_SYSTEM,
    PRECONDITIONED_MATRIX_FREE_SYSTEM,
)
from sofac.registry.components.ode import NEWTON_RAPHSON_SOLVER

if TYPE_CHECKING:
    from sofac.plan.planner import Planner


# StaticSolver's deprecated attributes -> the NewtonRaphsonSolver parameter SOFA's init sets from
# them, in SOFA's order (both relative tolerances land on relativeEstimateDifferenceThreshold).
_STATIC_LEGACY_FORWARDS = (
    ("newton_iterations", "maxNbIterationsNewton"),
    ("absolute_correction_tolerance_threshold", "absoluteEstimateDifferenceThreshold"),
    ("relative_correction_tolerance_threshold", "relativeEstimateDifferenceThreshold"),
    ("absolute_residual_tolerance_threshold", "absoluteResidualStoppingThreshold"),
    ("relative_residual_tolerance_threshold", "relativeEstimateDifferenceThreshold"),
)


# NewtonRaphsonSolver's parameters the static step reads (the maxNb* are counts).
_NEWTON_PARAMETERS = (
    "maxNbIterationsNewton",
    "absoluteResidualStoppingThreshold",
    "relativeInitialStoppingThreshold",
    "relativeSuccessiveStoppingThreshold",
    "absoluteEstimateDifferenceThreshold",
    "relativeEstimateDifferenceThreshold",
    "maxNbIterationsLineSearch",
    "lineSearchCoefficient",
)


def _newton_defaults() -> dict[str, float]:
    """SOFA's defaults of those parameters, from the registry (the NewtonRaphsonSolver a
    StaticSolver creates when the scene has none)."""
    resolution = registry.lookup("NewtonRaphsonSolver")
    assert resolution is not None
    fields = {name: resolution.spec.field(name) for name in _NEWTON_PARAMETERS}
    return {name: float(spec.default) for name, spec in fields.items() if spec is not None}


def _subtree(node: Any) -> list[Any]:
    """A node and its descendants, depth first."""
    nodes, pending = [], [node]
    while pending:
        current = pending.pop(0)
        nodes.append(current)
        pending[0:0] = list(current.children)
    return nodes


def new_group(planner: Planner, solver: CheckedComponent, index: int) -> Group | None:
    lowering = solver.spec.lowering if solver.spec else ""
    scheme = {
        "euler_explicit": Scheme.EULER,
        "central_difference": Scheme.EULER,
        "runge_kutta2": Scheme.RK2,
        "runge_kutta4": Scheme.RK4,
        "euler_implicit": Scheme.IMPLICIT,
        "static": Scheme.IMPLICIT,
        "newmark": Scheme.IMPLICIT,
        "variational": Scheme.IMPLICIT,
        "bdf": Scheme.IMPLICIT,
    }.get(lowering)
    if scheme is None:
        return None  # reported by _screen
    central = lowering == "central_difference"  # v first, then x with the new v: symplectic
    symplectic = central or (scheme is Scheme.EULER and bool(planner.value(solver.component, "symplectic")))
    group = Group(solver=solver.component, ident=f"g{index}", scheme=scheme, symplectic=symplectic)
    if central:
        # CentralDifferenceSolver: its rayleighMass; a = M^-1 f from the masses (accFromF) always
        value = planner.value(solver.component, "rayleighMass")
        group.central_difference = planner.buffer(
            solver.component, "rayleighMass", [float(value or 0.0)], role="param"
        )
        return group
    if lowering == "static" and not plan_static(planner, solver, group):
        return None
    if lowering == "euler_implicit" and not plan_implicit(planner, solver, group):
        return None
    if lowering == "newmark" and not plan_newmark(planner, solver, group):
        return None
    if lowering == "variational" and not plan_variational(planner, solver, group):
        return None
    if lowering == "bdf" and not plan_bdf(planner, solver, group):
        return None
    if scheme is Scheme.EULER:  # its linear solver serves only a non-diagonal mass: M a = f
        linear = solver.links.get("linearSolver")
        if not isinstance(linear, Component):
            linear = planner.checked.linear_solver_below(solver.component.node)
        spec = planner.checked.of(linear).spec if linear is not None else None
        if spec is not None and spec.lowering == "direct":
            group.linear_solver, group.assembled = linear, True
            direct_kind(planner, planner.checked.of(linear), group)
    return group


def plan_pcg(planner: Planner, linear: CheckedComponent, group: Group) -> bool:
    """SOFA's PCGLinearSolver: warm-started CG, optionally (block) Jacobi, SSOR or Warp
    preconditioned; with a PrecomputedWarpPreconditioner, no iteration at all (see below)."""
    component = linear.component
    group.linear_solver = component
    preconditioner = linear.links.get("preconditioner")
    if (
        isinstance(preconditioner, Component)
        and planner.value(component, "use_precond") is not False
        and getattr(planner.checked.of(preconditioner).spec, "lowering", "") == "precomputed_warp"
    ):
        if not precomputed_warp_is_inert(planner, planner.checked.of(preconditioner), group):
            return False
        group.inert_preconditioner = preconditioner
        return True
    group.pcg = {
        "iterations": planner.buffer(
            component, "iterations", [int(planner.value(component, "iterations") or 25)], "i64"
        ),
        "tolerance": planner.buffer(
            component, "tolerance", [float(planner.value(component, "tolerance"))], role="param"
        ),
    }
    if isinstance(preconditioner, Component) and planner.value(component, "use_precond") is not False:
        checked_preconditioner = planner.checked.of(preconditioner)
        spec = checked_preconditioner.spec
        lowering = spec.lowering if spec else ""
        kind = _PRECONDITIONERS.get(lowering)
        if lowering == "warp" and not warp_is_identity(planner, checked_preconditioner, group):
            return False
        if lowering == "direct" and not direct_preconditioner(planner, checked_preconditioner, group):
            return False
        if kind is None:
            planner.unsupported(
                planner.checked.of(preconditioner), f"sofac cannot compile {spec.name if spec else '?'} yet"
            )
            return False
        rate = _assembling_rate(planner, linear)
        if rate != 1 and lowering == "warp":
            planner.unsupported(
                linear, "a WarpPreconditioner refreshed less often than every step is not compiled yet"
            )
            return False
        # PreconditionedMatrixFreeSystem's counter: it starts at assemblingRate (the first solve
        # assembles), each solve increments it and assembles when it reaches the rate.
        group.pcg["assemblingRate"] = planner.buffer(component, "assemblingRate", [rate], "i64")
        group.pcg["assemblyCounter"] = planner.buffer(
            component, "assemblyCounter", [rate], "i64", role="state"
        )
        if kind is Preconditioner.SSOR:
            group.ssor_omega = planner.buffer(
                preconditioner, "omega", [float(planner.value(preconditioner, "omega"))], role="param"
            )
        group.preconditioner, group.assembled = kind, True
        if all(c is not preconditioner for c in group.preconditioners):  # a warp lists itself
            group.preconditioners.insert(0, preconditioner)
    return True


# The preconditioners' lowerings (registry) and how the runtime applies each.
_PRECONDITIONERS = {
    "jacobi": Preconditioner.JACOBI,
    "block_jacobi": Preconditioner.BLOCK_JACOBI,
    "ssor": Preconditioner.SSOR,
    "warp": Preconditioner.FACTORIZATION,
    "direct": Preconditioner.FACTORIZATION,
}


def _assembling_rate(planner: Planner, pcg: CheckedComponent) -> int:
    """The assemblingRate of a PCG's PreconditionedMatrixFreeSystem: its `linearSystem` link, else
    the first one in its node (SOFA's doCheckLinearSystem); 1 when SOFA creates a default one.
    (PCGLinearSolver's own update_step is a DeprecatedData: SOFA warns and ignores it.)"""
    system = pcg.links.get("linearSystem")
    if not isinstance(system, Component):
        system = next(
            (
                c
                for c in pcg.component.node.objects
                if (spec := planner.checked.of(c).spec) is not None
                and spec is PRECONDITIONED_MATRIX_FREE_SYSTEM
            ),
            None,
        )
    if not isinstance(system, Component):
        return 1
    spec = planner.checked.of(system).spec
    if spec is None or spec is not PRECONDITIONED_MATRIX_FREE_SYSTEM:
        return 1
    return max(int(planner.value(system, "assemblingRate") or 1), 1)


def direct_preconditioner(planner: Planner, direct: CheckedComponent, group: Group) -> bool:
    """A sparse direct solver (SparseLDLSolver...) as a PCG's preconditioner: SOFA links its linear
    system to the PCG's PreconditionedMatrixFreeSystem, which assembles it (mfact M + bfact B +
    kfact K, projected) when it refreshes; the solver factorises it when it is next applied
    (the assembly invalidates its factorisation) and applies it as a solve."""
    role = direct.spec.variant if direct.spec is not None else None
    if role == Variant.SVD:
        planner.unsupported(direct, "SVDLinearSolver as a PCG preconditioner is not compiled yet")
        return False
    if not assembles_everything(planner, direct):
        return False
    direct_kind(planner, direct, group)
    return True


def precomputed_warp_is_inert(planner: Planner, warp: CheckedComponent, group: Group) -> bool:
    """PrecomputedWarpPreconditioner as SOFA runs it: it sizes its precomputed inverse from its
    PrecomputedMatrixSystem's matrix, which nothing assembles (SOFA only allocates it, 0x0), so the
    inverse is 0x0 (the shared, empty matrix counts as already built: no precomputation) and the
    rotated product loops over no DOF: its output vector is left as it was. The PCG's first output
    is a fresh, zero vector, so r.z = 0 ends it before any iteration: dv keeps its start.
    The configurations where SOFA does something else are refused."""
    system = warp.links.get("linearSystem")
    system_spec = planner.checked.of(system).spec if isinstance(system, Component) else None
    if system_spec is None or system_spec is not PRECOMPUTED_MATRIX_SYSTEM:
        planner.unsupported(warp, "its linearSystem must link a PrecomputedMatrixSystem")
        return False
    if planner.value(warp.component, "use_rotations") is False:
        planner.unsupported(warp, "use_rotations false (SOFA then copies an empty product) is not compiled")
        return False
    if planner.value(warp.component, "share_matrix") is False:
        planner.unsupported(
            warp, "share_matrix false (SOFA then precomputes from files and solvers) is not compiled"
        )
        return False
    if group.static or group.newmark:
        planner.unsupported(warp, "it is compiled under an EulerImplicitSolver only")
        return False
    return True


def warp_is_identity(planner: Planner, warp: CheckedComponent, group: Group) -> bool:
    """WarpPreconditioner as sofac compiles it: its RotationMatrixSystem reassembles the main
    system every step (assemblingRate 1), which resets the rotations to identity, and its solver
    is a sparse direct one: the preconditioner is then that solver on this step's matrix."""
    system = warp.links.get("linearSystem")
    inner = warp.links.get("linearSolver")
    if not isinstance(inner, Component):
        solvers = [
            c for c in warp.component.node.objects if planner.checked.of(c).category is Category.LINEAR_SOLVER
        ]
        inner = next(
            (c for c in solvers if getattr(planner.checked.of(c).spec, "lowering", "") == "direct"), None
        )
    if isinstance(system, Component) and int(planner.value(system, "assemblingRate") or 1) != 1:
        planner.unsupported(
            warp,
            "a RotationMatrixSystem with assemblingRate > 1 (rotated factorisations) is not compiled yet",
        )
        return False
    spec = planner.checked.of(inner).spec if isinstance(inner, Component) else None
    if spec is None or spec.lowering != "direct":
        planner.unsupported(warp, "its linearSolver must be a sparse direct solver")
        return False
    group.llt = spec.variant is Variant.LLT
    group.preconditioners += [warp.component, inner]
    return True


def plan_implicit(planner: Planner, solver: CheckedComponent, group: Group) -> bool:
    """EulerImplicitSolver's parameters and its CG linear solver (matrix-free, as SOFA's)."""
    component = solver.component
    group.first_order = bool(planner.value(component, "firstOrder"))
    group.trapezoidal = bool(planner.value(component, "trapezoidalScheme"))
    for name in ("rayleighStiffness", "rayleighMass", "vdamping"):
        group.implicit[name] = planner.buffer(
            component, name, [float(planner.value(component, name) or 0.0)], role="param"
        )
    return plan_linear_solver(planner, solver, group)


def plan_newmark(planner: Planner, solver: CheckedComponent, group: Group) -> bool:
    """NewmarkImplicitSolver: Rayleigh damping, vdamping, gamma, beta; the linear solver."""
    component = solver.component
    for name in ("rayleighStiffness", "rayleighMass", "vdamping"):
        group.implicit[name] = planner.buffer(
            component, name, [float(planner.value(component, name) or 0.0)], role="param"
        )
    for name, default in (("gamma", 0.5), ("beta", 0.25)):
        value = planner.value(component, name)
        group.newmark[name] = planner.buffer(
            component, name, [float(default if value is None else value)], role="param"
        )
    group.newmark["started"] = planner.buffer(component, "started", [0], "i64", role="scratch")
    return plan_refactoring_solver(planner, solver, group)


def plan_refactoring_solver(planner: Planner, solver: CheckedComponent, group: Group) -> bool:
    """The linear solver of a scheme whose matrix changes within a step (Newmark, the
    variational Newton loop): PrecomputedLinearSolver's single factorisation is refused."""
    if not plan_linear_solver(planner, solver, group):
        return False
    if group.factor_once:
        name = solver.spec.name if solver.spec else solver.component.type_name
        planner.unsupported(
            planner.checked.of(group.linear_solver),
            f"PrecomputedLinearSolver under {name} is not compiled yet",
        )
        return False
    return True


def plan_variational(planner: Planner, solver: CheckedComponent, group: Group) -> bool:
    """VariationalSymplecticSolver (implicit variant): Newton's tolerance and iteration cap,
    Rayleigh damping, the Hamiltonian outputs and the energy file; then the linear solver."""
    component = solver.component
    if planner.value(component, "explicitIntegration"):
        planner.unsupported(
            solver,
            "explicitIntegration=true is not compiled yet (the implicit variant, the default, is)",
        )
        return False
    for name in ("rayleighStiffness", "rayleighMass"):
        group.implicit[name] = planner.buffer(
            component, name, [float(planner.value(component, name) or 0.0)], role="param"
        )
    error = planner.value(component, "newtonError")
    steps = planner.value(component, "steps")
    group.variational = {
        "newtonError": planner.buffer(
            component, "newtonError", [0.01 if error is None else float(error)], role="param"
        ),
        "steps": planner.buffer(component, "steps", [5 if steps is None else int(steps)], "i64"),
        "started": planner.buffer(component, "started", [0], "i64", role="scratch"),
        # m_incrementalPotentialEnergy: the potential at t = 0 plus -2 f.res at each step
        "incremental": planner.buffer(component, "incrementalPotentialEnergy", [0.0], role="state"),
        # outputs: hamiltonianEnergy, and the kinetic and potential parts the energy file shows
        "hamiltonianEnergy": planner.buffer(component, "hamiltonianEnergy", [0.0], role="state"),
        "energies": planner.buffer(component, "energies", [0.0, 0.0], role="state"),
    }
    computed = planner.value(component, "computeHamiltonian")
    group.hamiltonian = computed is None or bool(computed)
    incremental = planner.value(component, "useIncrementalPotentialEnergy")
    group.incremental_potential = incremental is None or bool(incremental)
    group.energy_file = str(planner.value(component, "file") or "")
    group.save_energy = bool(planner.value(component, "saveEnergyInFile"))
    return plan_refactoring_solver(planner, solver, group)


def screen_variational(planner: Planner, group: Group, owner: dict[int, Group]) -> None:
    """What sofac's VariationalSymplecticSolver cannot take: rigid frames (SOFA adds and
    subtracts their coordinates as vectors, quaternions included), and masses on mapped states
    (SOFA's momentum M v stops at the mappings: they would have no inertia)."""
    solver = planner.checked.of(group.solver)
    for state in group.states:
        if state.datatype.rigid:
            planner.unsupported(
                solver, f"VariationalSymplecticSolver on {state.datatype.name} is not compiled yet"
            )
    for checked in planner.checked:
        spec = checked.spec
        is_mass = checked.category is Category.MASS or (spec is not None and spec.variant is Variant.AND_MASS)
        state = planner.state_of(checked) if is_mass else None
        if state is not None and state.mapped and owner.get(id(state.component)) is group:
            planner.unsupported(
                checked,
                "a mass on a mapped state under VariationalSymplecticSolver is not compiled yet "
                "(SOFA's momentum M v leaves it out)",
            )


def _newton_solver(planner: Planner, solver: CheckedComponent) -> Component | None:
    """An ODE solver's NewtonRaphsonSolver: its `newtonSolver` link, else the first one in its node
    or below."""
    newton = solver.links.get("newtonSolver")
    if isinstance(newton, Component):
        return newton
    return next(
        (
            c
            for node in _subtree(solver.component.node)
            for c in node.objects
            if (spec := planner.checked.of(c).spec) is not None and spec is NEWTON_RAPHSON_SOLVER
        ),
        None,
    )


def _newton_buffers(
    planner: Planner, owner: Component, newton: Component | None, values: dict[str, float]
) -> dict[str, Buffer]:
    """The Newton parameters as buffers (those of `newton` where it has them, else `values`)."""
    for name, default in list(values.items()):
        value = planner.value(newton, name) if newton is not None else None
        values[name] = float(default if value is None else value)
    buffers = {}
    for name, value in values.items():
        if name.startswith("maxNb"):
            buffers[name] = planner.buffer(owner, name, [max(int(value), 0)], "i64")
        else:
            buffers[name] = planner.buffer(owner, name, [value], role="param")
    return buffers


def plan_static(planner: Planner, solver: CheckedComponent, group: Group) -> bool:
    """StaticSolver: Newton-Raphson on f(x) = 0 with the parameters of its NewtonRaphsonSolver
    (its `newtonSolver` link, else the first one in its node or below, else SOFA's defaults with
    the StaticSolver's deprecated attributes, as SOFA's init forwards them), then the linear solver."""
    component = solver.component
    newton = _newton_solver(planner, solver)
    values = _newton_defaults()
    if newton is None:
        for legacy, name in _STATIC_LEGACY_FORWARDS:
            value = planner.value(component, legacy)
            if value is not None:
                values[name] = float(value)
    group.static = _newton_buffers(planner, newton if newton is not None else component, newton, values)
    return plan_linear_solver(planner, solver, group)


def plan_bdf(planner: Planner, solver: CheckedComponent, group: Group) -> bool:
    """BDFOdeSolver: its order, Rayleigh damping, what it keeps between steps (the time list, the
    number of solves), the parameters of its NewtonRaphsonSolver (SOFA creates none: without one
    the solver is invalid and nothing moves, refused here), then the linear solver."""
    component = solver.component
    newton = _newton_solver(planner, solver)
    if newton is None:
        planner.unsupported(
            solver,
            "it needs a NewtonRaphsonSolver in its node or below (SOFA's is then invalid: nothing moves)",
        )
        return False
    order = max(int(planner.value(component, "order") or 0), 1)  # SOFA's callback makes 0 a 1
    for name in ("rayleighStiffness", "rayleighMass"):
        group.implicit[name] = planner.buffer(
            component, name, [float(planner.value(component, name) or 0.0)], role="param"
        )
    group.bdf = {
        "order": planner.buffer(component, "order", [order], "i64"),
        # the time list starts with the time at init (0); room for order + 2 (pushed, then trimmed)
        "times": planner.buffer(component, "times", np.zeros(order + 2), role="state"),
        "history": planner.buffer(component, "history", [1, 0], "i64", role="state"),  # times kept, solves
        "a": planner.buffer(component, "a", np.zeros(order + 1), role="scratch"),
        "b": planner.buffer(component, "b", np.zeros(order + 1), role="scratch"),
        **_newton_buffers(planner, newton, newton, _newton_defaults()),
    }
    return plan_refactoring_solver(planner, solver, group)


def screen_bdf(planner: Planner, group: Group) -> None:
    """What sofac's BDFOdeSolver cannot take: rigid frames (SOFA adds coordinates and derivatives
    as vectors) and mapped states (SOFA's residual r1 is never mapped: the force fields on mapped
    states see r1 = 0 in its K r1 product, and their masses see no velocity)."""
    solver = planner.checked.of(group.solver)
    for state in group.states:
        if state.datatype.rigid:
            planner.unsupported(solver, f"BDFOdeSolver on {state.datatype.name} is not compiled yet")
            return
    if group.mapped:
        planner.unsupported(
            solver,
            f"BDFOdeSolver with mapped mechanical states ({group.mapped[0].path}) is not compiled yet",
        )


def plan_linear_solver(planner: Planner, solver: CheckedComponent, group: Group) -> bool:
    """The implicit group's linear solver: CG (matrix-free, as SOFA's), PCG or a direct solver."""
    component = solver.component
    linear = solver.links.get("linearSolver")
    if not isinstance(linear, Component):
        linear = planner.checked.linear_solver_below(component.node)
    checked_linear = planner.checked.of(linear) if linear is not None else None
    if checked_linear is None or checked_linear.spec is None:
        return False  # E221, reported by the checker
    if checked_linear.spec.lowering == "pcg":
        return plan_pcg(planner, checked_linear, group)
    if checked_linear.spec.lowering == "minres":
        group.linear_solver = linear
        group.minres = {
            "iterations": planner.buffer(
                linear, "iterations", [int(planner.value(linear, "iterations") or 25)], "i64"
            ),
            "tolerance": planner.buffer(
                linear, "tolerance", [float(planner.value(linear, "tolerance"))], role="param"
            ),
        }
        return True
    if checked_linear.spec.lowering == "btd":
        return plan_btd(planner, checked_linear, group)
    if checked_linear.spec.lowering not in ("cg", "direct", "precomputed"):
        planner.unsupported(checked_linear, f"sofac cannot compile {checked_linear.spec.name} yet")
        return False
    group.linear_solver = linear
    if checked_linear.spec.lowering in ("direct", "precomputed"):
        if not assembles_everything(planner, checked_linear):
            return False
        group.assembled = group.direct = True
        group.factor_once = checked_linear.spec.lowering == "precomputed"
        direct_kind(planner, checked_linear, group)
        return True
    if (checked_linear.template or GRAPH_SCATTERED) != GRAPH_SCATTERED:
        # SOFA assembles the system matrix and runs CG on it (CRS, sparse or full: the same numbers)
        group.assembled = group.assembled_cg = True
    group.cg = {
        "iterations": planner.buffer(
            linear, "iterations", [int(planner.value(linear, "iterations") or 25)], "i64"
        ),
        "tolerance": planner.buffer(
            linear, "tolerance", [float(planner.value(linear, "tolerance"))], role="param"
        ),
        "threshold": planner.buffer(
            linear, "threshold", [float(planner.value(linear, "threshold"))], role="param"
        ),
        "solves": planner.buffer(linear, "solves", [0], "i64", role="scratch"),
    }
    return True


def direct_kind(planner: Planner, linear: CheckedComponent, group: Group) -> None:
    """The factorisation of a direct solver: L L^T (role "llt"), a dense SVD (role "svd", with
    SVDLinearSolver's minSingularValue) or L D L^T."""
    role = linear.spec.variant if linear.spec is not None else None
    group.llt = role == Variant.LLT
    if role == Variant.SVD:
        threshold = planner.value(linear.component, "minSingularValue")
        group.svd_threshold = planner.buffer(
            linear.component,
            "minSingularValue",
            [1e-6 if threshold is None else float(threshold)],
            role="param",
        )


def plan_btd(planner: Planner, linear: CheckedComponent, group: Group) -> bool:
    """BTDLinearSolver: the assembled, projected system read as a block-tridiagonal matrix of 6x6
    blocks (SOFA's BTDMatrix6d keeps no entry outside the three block diagonals), inverted by
    SOFA's Thomas algorithm every step. Its partial solves (subpartSolve) are not compiled."""
    if planner.value(linear.component, "subpartSolve"):
        planner.unsupported(linear, "subpartSolve=true is not compiled yet")
        return False
    if not assembles_everything(planner, linear):
        return False
    group.linear_solver = linear.component
    group.assembled = group.direct = group.btd = True
    return True


def screen_btd(planner: Planner, group: Group) -> None:
    """BTDLinearSolver's 6x6 blocks are the DOFs of Rigid3d (or Vec6d) states."""
    for state in group.states:
        if state.datatype.deriv_size != 6:
            planner.unsupported(
                planner.checked.of(group.linear_solver),
                f"BTDLinearSolver on a {state.datatype.name} state is not compiled "
                "(6x6 blocks: Rigid3d, Vec6d)",
            )
            return


def assembles_everything(planner: Planner, linear: CheckedComponent) -> bool:
    """The linear system a direct solver solves assembles M, K and the damping with the
    projections and the mapped components, as sofac's assembly does. Through a
    CompositeLinearSystem, that is its solverLinearSystem (else its first linear system, as
    SOFA picks); its other systems assemble only for display or output: nothing reads them."""
    system = linear.links.get("linearSystem")
    if not isinstance(system, Component):
        return True  # the default one SOFA creates: a MatrixLinearSystem
    checked = planner.checked.of(system)
    if checked.spec is not None and checked.spec is COMPOSITE_LINEAR_SYSTEM:
        chosen = checked.links.get("solverLinearSystem")
        if not isinstance(chosen, Component):
            listed = checked.links.get("linearSystems")
            chosen = next((c for c in listed or () if isinstance(c, Component)), None)
        if chosen is None:
            planner.unsupported(checked, "it needs a solverLinearSystem or linearSystems to solve")
            return False
        system, checked = chosen, planner.checked.of(chosen)
    plain = ("MatrixLinearSystem", "ConstantSparsityPatternSystem")
    if checked.spec is None or checked.spec.name not in plain:
        return True  # other systems are screened where they are planned
    flags = (
        "enableAssembly",
        "assembleStiffness",
        "assembleMass",
        "assembleDamping",
        "applyProjectiveConstraints",
        "applyMappedComponents",
    )
    off = [name for name in flags if planner.value(system, name) is False]
    if off:
        planner.unsupported(
            checked, f"{', '.join(off)}=false on the system a solver solves is not compiled yet"
        )
        return False
    return True
