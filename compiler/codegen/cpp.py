"""Code generation: a plan as C++17 source, the only place where C++ text is made.

The plan's calls (``sofac.plan.ir``) are spelled out here, with their slots bound to the vectors of
each place; the Jinja2 template (``templates/scene.cpp.j2``) only arranges them. Identifiers come
from the plan's counters and comments are reduced to printable ASCII, so no scene text can change
the code.
"""

from __future__ import annotations

import contextlib
import enum
import functools
import re
from pathlib import Path
from typing import Any

import jinja2
from sofac import __version__
from sofac.plan.ir import (
    CHILD,
    CONSTRAINT_PHASES,
    CONSTRAINT_REPORT_FIELDS,
    OFFSET,
    PARENT,
    STEP_PHASES,
    VECTOR,
    Aggregate,
    Arg,
    Buffer,
    BuiltSolver,
    Call,
    Collision,
    CollisionModel,
    Constant,
    ConstraintPhase,
    Count,
    Element,
    Env,
    FemMethod,
    Function,
    Group,
    LinearSystem,
    MappingOp,
    Note,
    Offset,
    Op,
    Plan,
    Preconditioner,
    Projection,
    Response,
    SelfFilter,
    Slot,
    SpringDamping,
    SpringFlags,
    Statement,
    StatePlan,
    TemplateArg,
    bind,
    origin_of,
)
from sofac.resources import cache_dir, resource_dir


def _comment(text: str) -> str:
    return re.sub(r"[^\x20-\x7e]", "?", text)


def _ptr(buffer: Buffer) -> str:
    return f"S.{buffer.ident}.data()"


def _size(buffer: Buffer) -> str:
    return f"Index(S.{buffer.ident}.size())"


# How the step's scope names the values of ir.Env, and the runtime's layout constants.
_ENV = {
    Env.ASSEMBLER: "A",
    Env.BAND: "T",
    Env.KFACT: "kfact",
    Env.MFACT: "mfact",
    Env.BFACT: "bfact",
    Env.FIXED: "D.fixed",
    Env.TIME: "S.time",
    Env.KINETIC: "kinetic",
    Env.POTENTIAL: "potential",
    Env.KINETIC_OUT: "&kinetic",
    Env.POTENTIAL_OUT: "&potential",
    Env.NONE: "nullptr",
    Env.CONTACTS: "S.contacts",
    Env.LAGRANGIAN: "S.lagrangian",
    Env.CONSTRAINT_PATTERN: "S.constraint_pattern",
}
_CONSTANTS = {Constant.TETRA_LANES: "sofac::TETRA_LANES"}
_PRECONDITIONER_TYPES = {
    Preconditioner.JACOBI: "JacobiPreconditioner",
    Preconditioner.BLOCK_JACOBI: "JacobiPreconditioner",
    Preconditioner.SSOR: "SsorPreconditioner",
}


def cpp_type(datatype: str) -> str:
    """The runtime's C++ type of a DataType (runtime/sofac/types.h)."""
    return f"sofac::{datatype}"


def _template(arg: TemplateArg) -> str:
    if isinstance(arg, bool):
        return "true" if arg else "false"
    if isinstance(arg, Constant):
        return _CONSTANTS[arg]
    if isinstance(arg, (SpringDamping, SpringFlags)):
        return f"sofac::{type(arg).__name__}::{arg.value}"
    if isinstance(arg, int):
        return str(arg)
    return cpp_type(arg)


def _templates(args: tuple[TemplateArg, ...]) -> str:
    return f"<{', '.join(_template(a) for a in args)}>" if args else ""


def _argument(arg: Arg) -> str:
    if isinstance(arg, Buffer):
        return _ptr(arg)
    if isinstance(arg, Count):
        return f"Index(S.{arg.buffer.ident}.size() / {arg.per})" if arg.per != 1 else _size(arg.buffer)
    if isinstance(arg, Element):
        return f"S.{arg.buffer.ident}[{arg.index}]"
    if isinstance(arg, Offset):
        return f"sofac::Assembler::kMapped + {arg.value}" if arg.mapped else str(arg.value)
    if isinstance(arg, Function):
        return f"sofac::{arg.name}"
    if isinstance(arg, LinearSystem):
        return f"S.direct_{arg.group}"
    if isinstance(arg, Aggregate):
        fields = ", ".join(_argument(f) for f in arg.fields)
        return f"sofac::{arg.type}{_templates(arg.templates)}{{{fields}}}"
    if isinstance(arg, Env):
        return _ENV[arg]
    if isinstance(arg, FemMethod):
        return f"sofac::FEM_{arg.name}"
    if isinstance(arg, BuiltSolver):
        return f"sofac::BuiltSolver::{arg.value}"
    if isinstance(arg, bool):
        return "true" if arg else "false"
    if isinstance(arg, (int, float)):
        return repr(arg)
    raise TypeError(f"an unbound {arg!r} reached code generation")


def _is_literal(arg: Arg) -> bool:
    """A number or flag printed as such (a reader cannot tell what it is without its name)."""
    return isinstance(arg, (bool, int, float)) and not isinstance(arg, enum.Enum)


def statement(item: Statement) -> str:
    """One C++ statement (or comment line) of the step."""
    if isinstance(item, Note):
        return f"// {_comment(item.text)}"
    count = len(item.args)
    arguments = ", ".join(
        (_label(item.kernel, i, count) if _is_literal(a) else "") + _argument(a)
        for i, a in enumerate(item.args)
    )
    text = f"sofac::{item.kernel}{_templates(item.templates)}({arguments});"
    if item.into is not None:
        text = f"{_ENV[item.into]} += {text}"
    if item.while_recording:
        text = f"if (A.recording()) {text}"
    return text


def _bound(item: Call, values: dict[Slot, Arg]) -> str:
    return statement(bind(item, values))


# Headers every scene includes: the library's ABI and the kernels the template itself calls.
_ALWAYS_INCLUDED = ("abi.h", "kernels.h")
# A top-level definition in a runtime header: `inline [attributes] type name(` or `struct Name`.
_DEFINITION = re.compile(
    r"^(?:__attribute__\(\([^)]*\)\)\s+)?(?:inline\s+[^;(]*?\b(\w+)\(|struct\s+(\w+))", re.M
)


@functools.cache
def _header_of() -> dict[str, str]:
    """Which runtime header defines each kernel and struct a plan's calls can name (read from the
    headers themselves, so there is no list to keep in step); the always-included ones win."""
    index: dict[str, str] = {}
    headers = sorted(
        (resource_dir("runtime") / "sofac").glob("*.h"), key=lambda h: h.name not in _ALWAYS_INCLUDED
    )
    for header in headers:
        for function, struct in _DEFINITION.findall(header.read_text()):
            index.setdefault(function or struct, header.name)
    return index


@functools.cache
def _parameter_names() -> dict[str, list[tuple[list[str], int]]]:
    """Each runtime function's parameter names, per overload, with the number it requires (the
    others have defaults), read from the headers: literal arguments are labelled with them."""
    signatures: dict[str, list[tuple[list[str], int]]] = {}
    for header in sorted((resource_dir("runtime") / "sofac").glob("*.h")):
        text = header.read_text()
        for match in _DEFINITION.finditer(text):
            if match.group(1) is None:
                continue
            parameters = _top_level_split(text, match.end())
            names = [_PARAMETER_NAME.findall(p.split("=")[0])[-1:] for p in parameters]
            required = sum(1 for p in parameters if "=" not in p)
            signatures.setdefault(match.group(1), []).append(([n[0] if n else "" for n in names], required))
    return signatures


def _top_level_split(text: str, start: int) -> list[str]:
    """The comma-separated parameters of the list opened just before ``start``."""
    depth, parts, current = 0, [], start
    for index in range(start, len(text)):
        char = text[index]
        if char in "(<{[":
            depth += 1
        elif char in ")>}]":
            if depth == 0:
                last = text[current:index].strip()
                return [*parts, last] if last or parts else parts
            depth -= 1
        elif char == "," and depth == 0:
            parts.append(text[current:index].strip())
            current = index + 1
    return parts


_PARAMETER_NAME = re.compile(r"\b([A-Za-z_]\w*)\s*(?:\[[^\]]*\])?\s*$")


def _label(kernel: str, position: int, count: int) -> str:
    """``/*name=*/`` for a literal argument, when every overload of ``kernel`` taking ``count``
    arguments names that parameter alike (nothing otherwise)."""
    candidates = {
        names[position]
        for names, required in _parameter_names().get(kernel, [])
        if required <= count <= len(names) and names[position]
    }
    return f"/*{candidates.pop()}=*/" if len(candidates) == 1 else ""


def _names(item: Statement) -> list[str]:
    if isinstance(item, Note):
        return []
    names = [item.kernel]
    pending = list(item.args)
    while pending:
        arg = pending.pop()
        if isinstance(arg, Function):
            names.append(arg.name)
        elif isinstance(arg, Aggregate):
            names.append(arg.type)
            pending.extend(arg.fields)
    return names


def _headers(plan: Plan) -> list[str]:
    """The runtime headers a plan's calls need, beyond the always-included ones."""
    statements: list[Statement] = []
    if plan.constraints is not None:
        statements += plan.constraints.calls()
    for group in plan.groups:
        statements += group.calls()
        # (J's assembly reaches the step through group.assemble, where an assembled system uses it)
        for mapping in (*group.mappings, *group.on_read):
            statements += [*mapping.apply, mapping.jacobian]
            statements += [c for c in (mapping.transpose, mapping.geometric) if c is not None]
        matrix = group.direct or group.preconditioned or group.assembled_cg
        for projection in group.projections:
            extra = (
                projection.project,
                projection.mark if matrix else None,
                projection.position,
                projection.project_velocity,
            )
            statements += [c for c in extra if c is not None]
    index = _header_of()
    needed = {index["BlockTridiagonal"]} if any(group.btd for group in plan.groups) else set()
    if plan.constraints is not None and plan.constraints.capacity:
        needed.add(index["PhaseClock"])  # the constraint step's timers (templates/scene.cpp.j2)
    for name in {n for item in statements for n in _names(item)}:
        if name not in index:
            raise KeyError(f"no runtime header defines sofac::{name}")
        needed.add(index[name])
    return sorted(needed - set(_ALWAYS_INCLUDED))


def _lap(field: str) -> int:
    """The constraint report's field a PhaseClock lap adds to."""
    return CONSTRAINT_REPORT_FIELDS.index(field)


def _uses(ops: list[Op], *values: Env) -> bool:
    """Whether a call of ``ops`` reads one of the scope's ``values`` (as an argument, also inside
    an aggregate, or as the sum it adds to): a function's parameter is named unused otherwise."""

    def within(arg: Arg) -> bool:
        if isinstance(arg, Aggregate):
            return any(within(f) for f in arg.fields)
        return isinstance(arg, Env) and arg in values

    return any(
        isinstance(c, Call) and (c.into in values or any(within(a) for a in c.args))
        for op in ops
        for c in op.calls
    )


def _maybe_unused(used: bool) -> str:
    """The attribute a parameter or a local takes when the code generated for this scene may not
    read it (the functions keep one signature whatever the scene holds)."""
    return "" if used else "[[maybe_unused]] "


class _OpView:
    def __init__(self, op: Op) -> None:
        self.origin = op.origin
        self.code = [statement(s) for s in op.calls]


class _BestEffortBytecodeCache(jinja2.FileSystemBytecodeCache):
    """Compiled templates kept when the folder takes them: a full disk only costs the next load
    its speed."""

    def dump_bytecode(self, bucket: jinja2.bccache.Bucket) -> None:
        with contextlib.suppress(OSError):
            super().dump_bytecode(bucket)


def _bytecode_cache() -> jinja2.BytecodeCache | None:
    folder = cache_dir() / "templates"
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None  # a read-only cache folder: compile the templates each time
    return _BestEffortBytecodeCache(str(folder))


@functools.lru_cache(maxsize=1)
def _environment() -> jinja2.Environment:
    return jinja2.Environment(
        loader=jinja2.FileSystemLoader(str(resource_dir("templates"))),
        # Compiled templates are kept next to the build cache: loading a cached scene in a new
        # process then skips Jinja2's template compilation (tens of milliseconds).
        bytecode_cache=_bytecode_cache(),
        trim_blocks=True,
        lstrip_blocks=True,
        keep_trailing_newline=True,
        undefined=jinja2.StrictUndefined,
        autoescape=False,  # C++, not HTML: every interpolated value is produced by sofac itself
    )


class _StateView:
    """A state as the template sees it."""

    def __init__(self, state: StatePlan) -> None:
        self.x, self.v, self.f, self.acc = state.x, state.v, state.f, state.acc
        self.dx, self.df = state.dx, state.df
        self.size = state.size
        self.width = state.datatype.deriv_size
        self.coord_width = state.datatype.coord_size
        self.cpp_type = cpp_type(state.datatype.name)
        self.rigid = state.datatype.rigid
        self.stages = state.stages
        self.path_comment = _comment(state.path)
        self.when = ""  # a condition on clearing its forces (see _GroupView)


class _MappingView:
    def __init__(self, mapping: MappingOp) -> None:
        self.origin = mapping.origin
        self.apply = [statement(c) for c in mapping.apply]
        parent, child = mapping.parent, mapping.child
        transpose, geometric = mapping.transpose, mapping.geometric
        dx = parent.dx is not None and child.dx is not None
        df = parent.df is not None and child.df is not None
        self.jacobian_dx = _bound(mapping.jacobian, _mapping_slots(mapping, "dx")) if dx else ""
        self.transpose_f = _bound(transpose, _mapping_slots(mapping, "f")) if transpose else ""
        self.transpose_df = _bound(transpose, _mapping_slots(mapping, "df")) if transpose and df else ""
        fixed = {Slot("parent", vector="dx"): parent.dx, Slot("parent", vector="df"): parent.df}
        usable = geometric is not None and parent.dx is not None and parent.df is not None
        self.geometric_df = _bound(geometric, fixed) if usable else ""  # type: ignore[arg-type]
        # J and J^T of a state only contacts read: only while one of its models is in contact (and
        # x and v too when its pipeline maps them when near).
        touching = " || ".join(f"S.contacts[{p}]->in_contact({m})" for p, m in mapping.while_in_contact)
        self.when = f"if ({touching}) " if touching else ""
        self.propagate = [self.when + line for line in self.apply] if mapping.mapped_when_near else self.apply


def _mapping_slots(mapping: MappingOp, vector: str) -> dict[Slot, Arg]:
    """A mapping's slots bound to its states' vectors of one kind (v, dx, f or df)."""
    slots: dict[Slot, Arg] = {PARENT: getattr(mapping.parent, vector), CHILD: getattr(mapping.child, vector)}
    for index, other in enumerate(mapping.inputs, start=1):
        slots[Slot("parent", input=index)] = getattr(other, vector)
    return slots


class _ProjectionView:
    def __init__(self, projection: Projection) -> None:
        state = projection.state
        self.origin = projection.origin
        self.velocity = projection.velocity
        project = projection.project

        def on(call: Call | None, vector: Buffer | None) -> str:
            return _bound(call, {VECTOR: vector}) if call is not None and vector is not None else ""

        self.on_v = on(projection.project_velocity or project, state.v)
        self.on_x = on(projection.position, state.x)
        self.on_acc = on(project, state.acc)
        self.on_f = on(project, state.f)
        self.on_df = on(project, state.df)
        self.on_r = on(project, state.stages.get("r"))


class _GroupView:
    """A group as the template reads it: views of its states, mappings and projections, and the
    values derived for the template; any other attribute is the group's own."""

    def __init__(self, group: Group, constraints: ConstraintPhase | None = None) -> None:
        self._group = group
        self.origin = origin_of(group.solver)
        self.states = [_StateView(s) for s in group.states]
        self.mapped = [_StateView(s) for s in group.mapped]
        self.all_states = [_StateView(s) for s in (*group.states, *group.mapped)]
        # A state only contacts read holds forces only while its model is in contact.
        when = {id(m.child): _MappingView(m).when for m in group.mappings}
        for view, state in zip(self.all_states, (*group.states, *group.mapped), strict=True):
            view.when = when.get(id(state), "")
        for view, state in zip(self.mapped, group.mapped, strict=True):
            view.when = when.get(id(state), "")
        self.mappings = [_MappingView(m) for m in group.mappings]
        self.transposes = [_MappingView(m) for m in reversed(group.mappings) if m.transpose]
        # Mapped on read: the collision points mapped when near, then the states the step leaves
        # out (parents before children: those may hang below the first, never above).
        self.on_read = [_MappingView(m) for m in group.mappings if m.mapped_when_near] + [
            _MappingView(m) for m in group.on_read
        ]
        self.projections = [_ProjectionView(p) for p in group.projections]
        # an assembled system matrix: assemble_<g>, its pattern at init
        self.matrix = group.direct or group.preconditioned or group.assembled_cg
        # PCGLinearSolver's preconditioner: a direct solver's factorisation, or a runtime
        # preconditioner object (its type, and the Jacobi block size).
        self.factored_preconditioner = group.preconditioner is Preconditioner.FACTORIZATION
        self.preconditioner_type = _PRECONDITIONER_TYPES.get(group.preconditioner, "")
        self.jacobi_block = 3 if group.preconditioner is Preconditioner.BLOCK_JACOBI else 1
        # The instance member holding it: a direct solver (CHOLMOD, also the preconditioners'
        # container) or the assembled CG's block rows and vectors.
        self.system = f"cg_{group.ident}" if group.assembled_cg else f"direct_{group.ident}"
        self.cg_block = group.cg_block if group.assembled_cg else 0
        self.linear_origin = origin_of(group.linear_solver) if group.linear_solver is not None else ""
        inert = group.inert_preconditioner
        self.inert_origin = origin_of(inert) if inert is not None else ""
        self.marks = [
            _bound(p.mark, {OFFSET: Offset(group.offset(p.state) or 0)})
            for p in group.projections
            if p.mark and self.matrix
        ]
        for phase in (*STEP_PHASES, "init"):
            setattr(self, phase, [_OpView(op) for op in getattr(group, phase)])
        # Which of its functions' parameters this group's calls read (the others are marked unused).
        geometric = [Op("", [m.geometric]) for m in group.mappings if m.geometric is not None]
        products = [*group.mass_dx, *group.stiffness_dx, *geometric]
        self.reads = {
            "assemble": {
                "A": _uses(group.assemble, Env.ASSEMBLER),
                "T": _uses(group.assemble, Env.BAND),
                "mfact": _uses(group.assemble, Env.MFACT),
                "kfact": _uses(group.assemble, Env.KFACT),
            },
            "mbk": {
                "mfact": bool(group.mass_dx),  # its `if (mfact != 0.0)` guard
                "kfact": _uses(products, Env.KFACT),
                "bfact": _uses(products, Env.BFACT),
            },
            "energy": {
                "S": bool(group.energy),
                "kinetic": _uses(group.energy, Env.KINETIC, Env.KINETIC_OUT),
                "potential": _uses(group.energy, Env.POTENTIAL, Env.POTENTIAL_OUT),
            },
            "finish": bool(group.mappings) or any(p.position or p.velocity for p in group.projections),
        }
        for view, state in zip(self.states, group.states, strict=True):
            view.offset = group.offset(state)
        self.trapezoidal = "0.5" if group.trapezoidal else "1.0"
        # FreeMotionAnimationLoop: states without a correction keep x and v over the free motion.
        self.frozen = [
            (_StateView(s), *constraints.saved[s.ident])
            for s in (constraints.frozen_in(group) if constraints else [])
        ]

    def __getattr__(self, name: str) -> Any:
        if name.startswith("_"):  # not the group's (and no recursion before _group is set)
            raise AttributeError(name)
        return getattr(self._group, name)


_SIDE = {"triangle": "kTriangle", "line": "kLine", "point": "kPoint", "sphere": "kSphere"}


_VIEW = {"triangle": "TriangleModel", "line": "LineModel", "point": "PointModel", "sphere": "SphereModel"}


def _model_view(index: int, model: CollisionModel) -> str:
    """The runtime's view of a collision model on the instance's buffers (proximity.h)."""
    x, cd = _ptr(model.state.x), repr(model.contact_distance)
    if model.kind == "triangle":
        here = f"C.models[{index}]"
        flags, normals = f"{here}.flags.data()", f"{here}.normals.data()"
        return f"{{{x}, {_ptr(model.cells)}, {flags}, {normals}, {model.elements}, {cd}}}"
    if model.kind == "line":
        return f"{{{x}, {_ptr(model.cells)}, {model.elements}, {cd}}}"
    if model.kind == "sphere":
        stride = _sphere_stride(model)
        return f"{{{x}, {stride}, {_sphere_radii(model)}, {model.radius!r}, {model.elements}, {cd}}}"
    return f"{{{x}, {model.elements}, {cd}}}"


def _sphere_stride(model: CollisionModel) -> int:
    """Numbers per sphere centre in its state: Vec3d, or a Rigid3d frame (centre, quaternion)."""
    return 7 if model.rigid else 3


def _sphere_radii(model: CollisionModel) -> str:
    """A sphere model's listRadius and its length (SphereModel's radii, n_radii)."""
    return f"{_ptr(model.radii)}, {_size(model.radii)}" if model.radii is not None else "nullptr, 0"


class _CollisionView:
    """The compiled contacts as the template arranges them: the setup at init (the pair table is
    a buffer), the model views of a step (one array per kind), their trees' updates, and one
    narrow-phase case per element test the scene has (the pairs sharing a test share its code)."""

    def __init__(self, collision: Collision, index: int) -> None:
        models = collision.models
        self.index = index
        self.origin = collision.origin
        alarm, contact = repr(collision.alarm_distance), repr(collision.contact_distance)
        self.method = f"const sofac::collide::Proximity method{{{alarm}, {contact}}};"
        used = sorted({i for p in collision.pairs for i in (p.first, p.second)})
        self.views: list[str] = []
        for kind, view in _VIEW.items():
            members = sorted((i for i in used if models[i].kind == kind), key=lambda i: models[i].view)
            if members:
                items = ",\n        ".join(_model_view(i, models[i]) for i in members)
                self.views.append(f"const sofac::collide::{view} {kind}s[] = {{\n        {items}}};")
        self.updates = []
        for i in used:
            model = models[i]
            normals = ""
            if model.kind == "triangle":
                normals = f", C.models[{i}].normals.data()" if model.compute_normals else ", nullptr"
            tree, view = f"C.models[{i}].tree", f"{model.kind}s[{model.view}]"
            self.updates.append(
                f"if (C.needs_update({i})) sofac::collide::update_tree({tree}, {view}{normals});"
            )
        self.lagrangian = collision.response is Response.FRICTION_CONTACT
        self.handle = "*S.lagrangian" if self.lagrangian else f"*S.contacts[{index}]"
        if collision.lmd is not None:
            self.views += _cone_views(collision, used)
        self.cases = []
        for number, test in enumerate(collision.tests):
            if test.name.startswith("local_min_distance::"):
                self.cases.append((number, test.name, _lmd_case(test.name)))
                continue
            if test.self_filter == "never":  # one point model: SOFA's filter refuses every pair
                self.cases.append(
                    (number, test.name, "// no element pair of one point model passes SOFA's filter")
                )
                continue
            first, second = test.kinds
            flags = "".join(f", {'true' if o else 'false'}" for o in test.options)
            views = f"{first}s[p.view[0]], e1, {second}s[p.view[1]], e2"
            call = f"sofac::collide::{test.name}(method, {views}{flags}, out);"
            if test.self_filter == "filter":  # models of one node: SOFA's canCollideWith first
                call = f"if (p.filter(e1, e2)) {call}"
            lambda_ = f"[&](Index e1, Index e2, sofac::collide::OutputList& out) {{ {call} }}"
            self.cases.append((number, test.name, f"C.narrow_phase(p, {lambda_});"))
        self.setup = [f"C.resize({len(models)}, {alarm}, {contact}, {collision.depth});"]
        for index, model in enumerate(models):
            here = f"C.models[{index}]"
            self.setup.append(f"// {_comment(model.origin)}")
            self.setup.append(f"{here}.kind = sofac::collide::ContactSide::{_SIDE[model.kind]};")
            self.setup.append(f"{here}.points = {model.state.size}; {here}.elements = {model.elements};")
            self.setup.append(
                f"{here}.contact_distance = {model.contact_distance!r}; "
                f"{here}.contact_stiffness = {model.contact_stiffness!r}; "
                f"{here}.moving = {'true' if model.moving else 'false'};"
            )
            if model.cells is not None:
                self.setup.append(f"{here}.cells = {_ptr(model.cells)};")
            if model.kind == "sphere":  # its radii, for the contacts' distances (x set by the response)
                radii, stride = _sphere_radii(model), _sphere_stride(model)
                self.setup.append(
                    f"{here}.sphere = {{nullptr, {stride}, {radii}, {model.radius!r}, {model.elements}, "
                    f"{model.contact_distance!r}}};"
                )
                if model.rigid:
                    self.setup.append(f"{here}.rigid = true;  // contact points fixed in the frames")
            if model.kind == "triangle":
                self.setup.append(f"{here}.flags.assign({model.elements}, 0);")
                self.setup.append(
                    f"sofac::collide::triangle_flags({_ptr(model.cells)}, {model.flagged}, "
                    f"{model.state.size}, {here}.flags.data());"
                )
        assert collision.table is not None
        table, rows = _ptr(collision.table), len(collision.pairs)
        self.setup.append(f"for (Index k = 0; k < {rows}; ++k) {{  // the pair table: {_VIEW_COLUMNS}")
        self.setup.append(f"    const Index* row = {table} + 7 * k;")
        self.setup.append("    C.add_pair(row[0], row[1], row[2], row[3], row[4], row[5], row[6]);")
        self.setup.append("}")
        self.setup += _pair_settings(collision)
        # points mapped only when near: their parent, enclosure's growth, saved positions, models
        self.lazy = [
            (_comment(z.origin), statement(z.previous), statement(z.current)) for z in collision.lazy
        ]
        for number, lazy in enumerate(collision.lazy):
            self.setup.append(f"// {_comment(lazy.origin)}: mapped when near")
            self.setup.append(
                f"C.add_lazy_points({_ptr(lazy.parent)}, {lazy.parent_points}, {lazy.spread!r}, "
                f"{lazy.rounding!r}, {_ptr(lazy.saved)});"
            )
            self.setup.extend(f"C.set_lazy({model}, {number});" for model in lazy.models)
        self.setup.append("C.finish_setup();")
        if self.lagrangian:
            rows, static = collision.row_capacity + collision.static_rows, collision.static_rows
            bodies = max((b.body for b in collision.bodies), default=-1) + 1
            self.setup.append(f"C.setup_lagrangian({collision.mu!r}, {static}, {bodies});")
            for i, b in enumerate(collision.bodies):
                given = (b.free, b.frames, b.offsets, b.subset, b.nodes, b.weights, b.element_nodes)
                pointers = ", ".join(_ptr(p) if p is not None else "nullptr" for p in given)
                self.setup.append(f"C.lagrangian[{i}] = {{{b.body}, {pointers}, {b.width}}};")
            self.setup.append(f"C.rank = {{{', '.join(str(r) for r in collision.ranks)}}};")
            self.setup.append(f"C.reserve_rows({rows});")
        self.fit = ""  # friction_contact: the problem's buffers grown with the rows (lagrangian_fit)
        if self.lagrangian and collision.problem:
            vectors = ", ".join(f"S.{b.ident}" for b in collision.problem)
            self.fit = f"sofac::lagrangian_fit(S.lagrangian, S.lagrangian_retired, {vectors});"
        self.positions = "".join(f"\n        {_ptr(m.state.x)}," for m in models)
        assert collision.report is not None
        self.report = _ptr(collision.report)


_VIEW_COLUMNS = "first, second, placement, id bound, test, views"


def _pair_settings(collision: Collision) -> list[str]:
    """What a pair of models of one node needs besides its row (SOFA's element filter; the motion
    watch skips it), and the pairs whose models' contactResponse is "nullptr"."""
    lines = []
    for k, pair in enumerate(collision.pairs):
        here = f"C.pairs[{k}]"
        if pair.self_filter not in (SelfFilter.NONE, SelfFilter.NEVER):
            first = collision.models[pair.first]
            around = first.edges_around_vertex
            adjacency = f"{{{_ptr(around[0])}, {_ptr(around[1])}}}" if around is not None else "{}"
            cells = _ptr(first.cells) if first.cells is not None else "nullptr"
            rule = f"sofac::collide::SelfCollisionFilter::{pair.self_filter.value}"
            lines.append(f"{here}.filter = {{{rule}, {cells}, {adjacency}}};")
        if pair.one_node:
            lines.append(f"{here}.one_node = true;  // models of one node: one state")
        if not pair.respond:
            lines.append(f'{here}.respond = false;  // contactResponse "nullptr": no contact')
    return lines


_LMD = "sofac::collide::local_min_distance"

# LocalMinDistance's element tests, with each model's cone (by its view among its kind).
_LMD_ARGUMENTS = {
    "point_point": "points[v0], e1, point_cones[v0], points[v1], e2, point_cones[v1]",
    "line_point": "lines[v0], e1, line_cones[v0], points[v1], e2, point_cones[v1]",
    "line_line": "lines[v0], e1, line_cones[v0], lines[v1], e2, line_cones[v1]",
    "triangle_point": "triangles[v0], e1, triangle_both[v0], points[v1], e2, point_cones[v1]",
}


def _lmd_case(name: str) -> str:
    test = name.split("::")[1]
    views = "const Index v0 = p.view[0], v1 = p.view[1];"
    body = f"{views} {_LMD}::{test}(method, lmd, {_LMD_ARGUMENTS[test]}, out);"
    return f"C.narrow_phase(p, [&](Index e1, Index e2, sofac::collide::OutputList& out) {{ {body} }});"


def _cone_views(collision: Collision, used: list[int]) -> list[str]:
    """LocalMinDistance's options and the cones of the paired models, by view (runtime PointCone,
    LineCone; null where SOFA accepts without reading a topology)."""
    assert collision.lmd is not None
    filter_, angle, factor, filters = collision.lmd
    b = lambda v: "true" if v else "false"  # noqa: E731
    lines = [f"const {_LMD}::Options lmd{{{b(filter_)}, {angle!r}, {factor!r}, {b(filters)}}};"]
    models = collision.models
    for kind, cone in (("point", "PointCone"), ("line", "LineCone")):
        members = sorted((i for i in used if models[i].kind == kind), key=lambda i: models[i].view)
        names = []
        for i in members:
            model = models[i]
            if model.cone is None:
                names.append("nullptr")
                continue
            x = _ptr(model.state.x)
            parts = [_ptr(c) for c in model.cone]
            if kind == "point":
                tri, edges, tav_o, tav, eav_o, eav = parts
                fields = f"{x}, {tri}, {edges}, {{{tav_o}, {tav}}}, {{{eav_o}, {eav}}}, false"
            else:
                tri, tae_o, tae = parts
                fields = f"{x}, {tri}, {{{tae_o}, {tae}}}, false"
            lines.append(f"const {_LMD}::{cone} {kind}_cone_{i}{{{fields}}};")
            names.append(f"&{kind}_cone_{i}")
        items = ", ".join(names) if names else "nullptr"
        lines.append(f"[[maybe_unused]] const {_LMD}::{cone}* const {kind}_cones[] = {{{items}}};")
    triangles = sorted((i for i in used if models[i].kind == "triangle"), key=lambda i: models[i].view)
    both = ", ".join(b(models[i].both_side) for i in triangles) or "false"
    lines.append(f"[[maybe_unused]] const bool triangle_both[] = {{{both}}};")
    return lines


def _initialises(group: Group) -> bool:
    """Whether sofac_init does anything for a group: its init calls, its system's pattern, its
    projections of x, its mappings."""
    matrix = group.direct or group.preconditioned or group.assembled_cg
    return bool(group.init or matrix or group.mappings or any(p.position for p in group.projections))


def generate_source(plan: Plan) -> str:
    """The C++ source of a plan's step (deterministic: same plan, same text). Compiled for
    threads, groups that share no buffer step in parallel (Plan.parallel_groups)."""
    template = _environment().get_template("scene.cpp.j2")
    buffers: list[dict[str, Any]] = [
        {"ident": b.ident, "kind": b.kind, "comment": _comment(f"{b.key} ({b.role})")} for b in plan.buffers
    ]

    collisions = [_CollisionView(c, k) for k, c in enumerate(plan.collisions) if c.pairs]
    on_read = any(g.on_read or any(m.mapped_when_near for m in g.mappings) for g in plan.groups)
    source = template.render(
        version=__version__,
        scene_file=_comment(plan.scene_file),
        buffers=buffers,
        groups=[_GroupView(g, plan.constraints) for g in plan.groups],
        constraints=plan.constraints,
        constraint_phases=[
            (name, [_OpView(op) for op in getattr(plan.constraints, name)], _lap(f"{name}_seconds"))
            for name in CONSTRAINT_PHASES
        ]
        if plan.constraints
        else [],
        constraint_laps={part: _lap(f"{part}_seconds") for part in ("detection", "free_motion", "finish")},
        any_direct=any(g.direct or g.preconditioned for g in plan.groups),
        on_read=on_read,
        any_assembled_cg=any(g.assembled_cg for g in plan.groups),
        headers=_headers(plan),
        dt=plan.dt,
        threads=plan.threads,
        guard=plan.contact_guard,
        collisions=collisions,
        lagrangian=any(c.response is Response.FRICTION_CONTACT and c.pairs for c in plan.collisions),
        parallel_groups=plan.parallel_groups,
        ptr=_ptr,
        size=_size,
        maybe_unused=_maybe_unused,
        init_reads_instance=bool(collisions)
        or on_read
        or any(_initialises(g) for g in plan.groups)
        or bool(plan.constraints and plan.constraints.capacity),
    )
    # Comments name scene files relative to the scene's folder: a moved scene keeps its source,
    # and so its cache entry. (Nothing else in the source comes from a path.)
    scene = Path(plan.scene_file)
    for folder in sorted({str(scene.resolve().parent), str(scene.parent)} - {"."}, key=len, reverse=True):
        source = source.replace(folder + "/", "")
    return source
