"""Scene utilities: the animation loop, plugin loading and settings."""

from __future__ import annotations

from ..fields import Bool, FileName, Ints, Real, Reals, Text, Words
from ..spec import Category, ComponentSpec, FieldSpec, Variant
from .common import ANIMATION_LOOP_FIELDS, TASK_SCHEDULER_FIELDS

DEFAULT_ANIMATION_LOOP = ComponentSpec(
    name="DefaultAnimationLoop",
    category=Category.ANIMATION_LOOP,
    module="Sofa.Simulation.Core",
    doc="The standard step: collision, then each ODE solver integrates its subtree, then mappings "
    "(added automatically when missing).",
    supported=True,
    fields=(
        FieldSpec("parallelODESolving", Bool(), False, "integrate independent subtrees in parallel"),
        *ANIMATION_LOOP_FIELDS,
    ),
)

REQUIRED_PLUGIN = ComponentSpec(
    name="RequiredPlugin",
    category=Category.UTILITY,
    module="Sofa.Simulation.Core",
    doc="Loads SOFA modules/plugins (name= or pluginName=); no physics.",
    supported=True,
    fields=(
        FieldSpec("pluginName", Words(), doc="plugins to load (default: the component's name)"),
        FieldSpec("suffixMap", Words(), doc="standard-to-custom library suffix pairs"),
        FieldSpec("stopAfterFirstNameFound", Bool(), False),
        FieldSpec("stopAfterFirstSuffixFound", Bool(), True),
        FieldSpec("requireOne", Bool(), False, "error if no plugin could be loaded"),
        FieldSpec("requireAll", Bool(), True, "error if any plugin could not be loaded"),
        FieldSpec("loadedPlugins", Words(), doc="output: plugins loaded"),
    ),
)

TASK_SCHEDULER_SETTINGS = ComponentSpec(
    name="TaskSchedulerSettings",
    category=Category.UTILITY,
    module="Sofa.Simulation.Core",
    doc="Configures the global task scheduler (threads).",
    supported=True,  # no part in the step: accepted and ignored by the compiler
    fields=TASK_SCHEDULER_FIELDS,
)

CONSTRAINT_ATTACH_BUTTON_SETTING = ComponentSpec(
    name="ConstraintAttachButtonSetting",
    category=Category.UTILITY,
    module="Sofa.GUI.Component",
    doc="GUI setting: mouse picking attaches objects with Lagrangian constraints.",
    supported=True,  # no part in the step: accepted and ignored by the compiler
    fields=(FieldSpec("button", Text(), doc="mouse button"),),
)

API_VERSION = ComponentSpec(
    name="APIVersion",
    category=Category.UTILITY,
    module="Sofa.Component.SceneUtility",
    doc="Declares the SOFA API level the scene was written for (e.g. 17.06).",
    unsupported_reason="APIVersion (legacy compatibility switches) is not supported",
    fields=(FieldSpec("level", Text(), doc="API level of the scene"),),
)

ADD_DATA_REPOSITORY = ComponentSpec(
    name="AddDataRepository",
    category=Category.UTILITY,
    module="Sofa.Component.SceneUtility",
    doc="Adds a directory (relative to the scene's) to the data file search path, after the others.",
    supported=True,
    variant=Variant.DATA_REPOSITORY,
    fields=(FieldSpec("path", Text(), doc="directory to add"),),
)

WRITE_STATE = ComponentSpec(
    name="WriteState",
    category=Category.UTILITY,
    module="Sofa.Component.Playback",
    doc="Writes its node's MechanicalObject to a text file at the beginning of steps (T=, X=, V=); "
    "sofac records the same with `sofac run --export-states`.",
    supported=True,
    fields=(
        FieldSpec("filename", FileName(output=True), doc="output file (.gz compresses)"),
        FieldSpec("writeX", Bool(), True, "write positions"),
        FieldSpec("writeX0", Bool(), False, "write rest positions"),
        FieldSpec("writeV", Bool(), False, "write velocities"),
        FieldSpec("writeF", Bool(), False, "write forces"),
        FieldSpec("time", Reals(), (0.0,), "times at which to write"),
        FieldSpec("period", Real(), 0.0, "period between writes (0: every step)"),
        FieldSpec("DOFsX", Ints(), doc="only these DOFs' positions"),
        FieldSpec("DOFsV", Ints(), doc="only these DOFs' velocities"),
        FieldSpec("stopAt", Real(), 0.0, "stop writing after this time (0: never)"),
        FieldSpec("keperiod", Real(), 0.0, "kinetic-energy threshold period"),
    ),
)

COMPONENTS = (
    WRITE_STATE,
    DEFAULT_ANIMATION_LOOP,
    REQUIRED_PLUGIN,
    TASK_SCHEDULER_SETTINGS,
    CONSTRAINT_ATTACH_BUTTON_SETTING,
    API_VERSION,
    ADD_DATA_REPOSITORY,
)
