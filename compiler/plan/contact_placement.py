"""Where a compiled pipeline's contact forces go: each simulated model's forces (and, with a static
partner, K dx and its assembled blocks) in the group integrating its state, and the pairs of two
simulated models in the group of the solver integrating the pipeline's node, when one does.
Used by plan/contacts.py."""

from __future__ import annotations

from typing import TYPE_CHECKING

from sofac.check.checker import CheckedComponent

from .ir import Aggregate, Arg, Collision, Env, Group, Op, Scheme, call

if TYPE_CHECKING:
    from sofac.plan.planner import Planner


def pipeline_group(planner: Planner, pipeline: CheckedComponent, owner: dict[int, Group]) -> Group | None:
    """The group of the solver that integrates the pipeline's node, if one does."""
    solver = planner.checked.solver_of(pipeline.component.node)
    if solver is None:
        return None
    return next((g for g in owner.values() if g.solver is solver.component), None)


def place_in_group(
    planner: Planner, collision: Collision, pipeline: int, group: Group, owner: dict[int, Group]
) -> None:
    """The pairs of two simulated models when a solver integrates the pipeline's node: SOFA places
    their force fields there, inside that solver's group: evaluated in each of its force
    evaluations and (implicit) K dx products, both models moving, in SOFA's contact order."""
    grouped = [p for p in collision.pairs if p.grouped]
    if not grouped:
        return
    models = collision.models
    involved = sorted({i for p in grouped for i in (p.first, p.second)})
    for index in involved:
        if owner.get(id(models[index].state.component)) is not group:
            solver = planner.checked.of(group.solver)
            planner.unsupported(
                solver,
                f"the contacts of {models[index].origin} are placed at the collision pipeline's node, "
                "which this solver integrates, but this solver does not integrate the model's state",
            )
            return
    for solver in (group.linear_solver,):
        if group.assembled and solver is not None:
            planner.unsupported(
                planner.checked.of(solver),
                "penalty contacts between two simulated models in its group (the pipeline's node is "
                "integrated by its solver) change the system's couplings every step; an assembled "
                "system keeps one pattern: not compiled yet (a matrix-free CGLinearSolver is)",
            )
            return

    def vectors(name: str) -> Aggregate:
        fields: list[Arg] = []
        for i, model in enumerate(models):
            buffer = getattr(model.state, name) if i in involved else None
            fields.append(buffer if buffer is not None else Env.NONE)
        return Aggregate("ModelVectors", tuple(fields), (len(models),))

    where = f"contact forces of {collision.origin} between simulated models"
    group.forces.append(
        Op(where, [call("contact_group_add_force", Env.CONTACTS, pipeline, vectors("f"), vectors("x"))])
    )
    if group.scheme is Scheme.IMPLICIT and all(models[i].state.dx is not None for i in involved):
        group.stiffness_dx.append(
            Op(
                where,
                [
                    call(
                        "contact_group_add_dforce",
                        Env.CONTACTS,
                        pipeline,
                        vectors("df"),
                        vectors("dx"),
                        Env.KFACT,
                    )
                ],
            )
        )


def place_contacts(planner: Planner, collision: Collision, pipeline: int, owner: dict[int, Group]) -> None:
    """Each simulated model's contact forces in the group integrating its state: in every force
    evaluation and, for its contacts with static models, in every K dx product. (Pairs placed in
    the group of the pipeline's node are place_in_group's.)"""
    in_pairs = {i for p in collision.pairs if not p.grouped for i in (p.first, p.second)}
    for index, model in enumerate(collision.models):
        if index not in in_pairs or not model.simulated:
            continue
        group = owner.get(id(model.state.component))
        if group is None:
            continue  # nothing integrates it: the forces on it go nowhere, as in SOFA
        where = f"contact forces on {model.origin}"
        state = model.state
        group.forces.append(
            Op(where, [call("contact_add_force", Env.CONTACTS, pipeline, index, state.f, state.x)])
        )
        static_partner = any(
            not collision.models[p.second if p.first == index else p.first].simulated
            for p in collision.pairs
            if index in (p.first, p.second)
        )
        if group.assembled and static_partner:  # A += kfact K: blocks between each element's points
            offset = group.assembly_offset(state, planner.checked.of(state.component))
            assembly = (Env.CONTACTS, pipeline, index, Env.ASSEMBLER, offset, Env.KFACT)
            group.assemble.append(Op(where, [call("contact_assemble", *assembly)]))
            if group.btd and model.rigid:
                planner.unsupported(
                    planner.checked.of(model.state.component),
                    f"the contacts of {model.origin} (spheres on Rigid3d frames) under BTDLinearSolver "
                    "are not compiled yet",
                )
            elif group.btd:  # SOFA's coupling blocks with the static side, read as the system's DOFs
                group.assemble.append(
                    Op(where, [call("contact_assemble_static_coupling", *assembly, Env.BAND)])
                )
            elif group.linear_solver is not None:
                solver = group.linear_solver
                planner.diags.add(
                    "W232",
                    solver.loc,
                    f"{solver.type_name} at line {solver.loc.line} assembles the contacts of "
                    f"{model.origin} with a static model: SOFA's MatrixLinearSystem also adds their "
                    "coupling blocks at the static contact points' indices, read as this system's "
                    "DOFs; sofac leaves them out for this solver, so its solve can differ from SOFA's "
                    "while they touch",
                    "BTDLinearSolver and a matrix-free CGLinearSolver reproduce SOFA here",
                )
        if group.scheme is Scheme.IMPLICIT and static_partner and state.dx is not None:
            group.stiffness_dx.append(
                Op(
                    where,
                    [
                        call(
                            "contact_add_dforce", Env.CONTACTS, pipeline, index, state.df, state.dx, Env.KFACT
                        )
                    ],
                )
            )
