"""The plan as text for people: its effects and its schedule (``sofac inspect``)."""

from __future__ import annotations

from sofac.plan.ir import (
    Plan,
    Response,
    Scheme,
    origin_of,
)


def format_effects(plan: Plan) -> str:
    """The effects the step contains, and those left out, for ``sofac inspect --effects``."""
    width = max((len(e) for e, _, _ in plan.effects), default=0)
    return "\n".join(f"{effect:<{width}}  {origin}: {detail}" for effect, origin, detail in plan.effects)


def format_schedule(plan: Plan) -> str:
    """The plan as text, for ``sofac inspect --schedule``."""
    lines = [
        f"scene {plan.scene_file}",
        f"dt = {float(plan.dt.initial[0])!r}, gravity = {plan.gravity.initial.tolist()}",
    ]
    for group in plan.groups:
        scheme = {
            Scheme.EULER: "central difference"
            if group.central_difference is not None
            else "symplectic Euler"
            if group.symplectic
            else "explicit Euler",
            Scheme.RK2: "RK2 (midpoint)",
            Scheme.RK4: "RK4",
            Scheme.IMPLICIT: "static equilibrium (Newton-Raphson)"
            if group.static
            else "Newmark"
            if group.newmark
            else "variational symplectic (implicit midpoint)"
            if group.variational
            else f"BDF of order {int(group.bdf['order'].initial[0])} (Newton-Raphson)"
            if group.bdf
            else "implicit Euler",
        }[group.scheme]
        lines.append(f"solver {origin_of(group.solver)}: {scheme}")
        lines.append(
            "  independent states: "
            + ", ".join(f"{s.path} <{s.datatype.name}> x{s.size}" for s in group.states)
        )
        if group.mapped:
            lines.append(
                "  mapped states: "
                + ", ".join(f"{s.path} <{s.datatype.name}> x{s.size}" for s in group.mapped)
            )
        sections: list[tuple[str, list[str]]] = [
            ("propagate x, v down the mappings", [m.origin for m in group.mappings]),
            ("reset forces, accumulate forces and gravity", [op.origin for op in group.forces]),
            ("map forces up (J^T), child first", [m.origin for m in reversed(group.mappings) if m.transpose]),
        ]
        if group.scheme is Scheme.IMPLICIT:
            if group.static:
                rhs, system = "b = f, projected", "Newton iterations: solve -K dx = f, x += alpha dx"
            elif group.newmark:
                rhs = "b = f + (-rm M + (rk + h) K) v + (...) a, projected"
                system = "solve ((1 + h gamma rm) M - (h^2 beta + h gamma rk) K) a' = b"
            elif group.variational:
                rhs = "Newton iterations: b = f(x + res) - K res + (2/h) p, projected"
                system = "solve ((4/h^2 + 4 rm/h) M - (1 + 4 rk/h) K) res = b"
            elif group.first_order:
                rhs, system = "b = f, projected (firstOrder)", "solve (M - h K) v' = b"
            else:
                rhs, system = (
                    "b = h (f - rm M v + (h + rk) K v), projected",
                    "solve ((1 + h rm) M - h (h + rk) K) dv = b",
                )
            sections += [
                (f"{rhs}; M dx", [op.origin for op in group.mass_dx]),
                ("K dx", [op.origin for op in group.stiffness_dx]),
            ]
            if group.assembled_cg:
                block = group.cg_block
                sections.append(
                    (
                        f"assemble mfact M + kfact K (rows of {block}x{block} blocks), projected",
                        [op.origin for op in group.assemble],
                    )
                )
            on = " on the assembled matrix" if group.assembled_cg else ""
            sections.append((f"{system} with {origin_of(group.linear_solver)}{on}", []))
        else:
            sections.append(("a = M^-1 f", [op.origin for op in group.accelerations]))
        sections.append(("project constraints", [p.origin for p in group.projections]))
        for title, origins in sections:
            lines.append(f"  {title}:")
            lines.extend(f"    - {origin}" for origin in origins)
        lines.append("  update x, v; propagate again")
        if group.on_read:
            lines.append("  mapped only when read from Python (nothing in the step reads them):")
            lines.extend(f"    - {m.origin} -> {m.child.path}" for m in group.on_read)
    lines.extend(_constraint_schedule(plan))
    idle = [s for s in plan.states if not s.mapped and not any(s in g.states for g in plan.groups)]
    for state in idle:
        lines.append(f"not integrated (no ODE solver): {state.path}")
    for component, why in plan.ignored:
        lines.append(f"kept out of the step: {origin_of(component)}: {why}")
    return "\n".join(lines)


def _contact_rows(plan: Plan) -> str:
    """How many of the phase's rows its Lagrangian contacts are reserved, and where they come from."""
    for collision in plan.collisions:
        if collision.response is Response.FRICTION_CONTACT and collision.pairs:
            per = 3 if collision.mu > 0 else 1
            return (
                f" (reserved: {collision.static_rows} of the scene's constraints, then "
                f"{collision.row_capacity // per} contacts of {per} row(s) from {collision.origin}, "
                "detected each step; more contacts double the reserve, a growth in its contactReport)"
            )
    return ""


def _constraint_schedule(plan: Plan) -> list[str]:
    """FreeMotionAnimationLoop's constraint phase: the solver and its settings, the corrections,
    the states SOFA leaves frozen."""
    phase = plan.constraints
    if phase is None:
        return []
    settings = ", ".join(f"{name}={float(buffer.initial[0])!r}" for name, buffer in phase.settings.items())
    solver = phase.solver or "SOFA's default BlockGaussSeidelConstraintSolver"
    lines = [
        f"constraint phase of {phase.loop} (the solves above are the free motion):",
        f"  solver {solver}: {phase.method}" + (f" ({settings})" if settings else ""),
        f"  constraint rows: {phase.capacity}"
        + (" (x = x_free, v = v_free: each correction adds C J^T 0)" if not phase.capacity else "")
        + _contact_rows(plan),
        "  corrections:",
    ]
    lines.extend(f"    - {c.origin}: {c.kind} on {c.state.path}" for c in phase.corrections)
    lines.extend(
        f"  frozen (no constraint correction, SOFA never writes its free motion back): {s.path}"
        for s, _ in phase.frozen
    )
    return lines
