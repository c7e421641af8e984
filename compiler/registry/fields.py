"""Typed field values: how one attribute's text becomes a value, and how it is written back.

Each field of a component spec has one of these types. ``parse`` turns SOFA's text form into a
Python value (numbers as numpy arrays for anything bulk) or raises :class:`FieldValueError` with
the diagnostic code to report; ``check_count`` validates the number of values once the DataType of
the component is known; ``format`` writes a value back in SOFA's text form.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any

import numpy as np

from .datatypes import DataType


class FieldValueError(ValueError):
    """A value that does not parse (E204), has the wrong count (E205) or is not finite (E206)."""

    def __init__(self, message: str, code: str = "E204", hint: str = "", value: Any = None) -> None:
        super().__init__(message)
        self.code = code
        self.hint = hint
        # For a warning (code W...): the value SOFA reads from the text anyway (None: its default).
        self.value = value


def _format_real(x: float) -> str:
    return repr(float(x)) if not float(x).is_integer() or abs(x) >= 1e16 else str(int(x))


# One number as C++'s stream extraction reads it (the longest prefix strtod accepts).
_STREAM_REAL = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?")


def _stream_reals(token: str) -> list[str] | None:
    """A word SOFA's ``>> double`` reads as several numbers ("0-0.707107" is 0 then -0.707107)."""
    parts = []
    position = 0
    while position < len(token):
        match = _STREAM_REAL.match(token, position)
        if match is None:
            return None
        parts.append(match.group())
        position = match.end()
    return parts


def parse_reals(text: str) -> np.ndarray:
    """Whitespace-separated reals (SOFA also tolerates commas and brackets in vectors)."""
    tokens = text.replace(",", " ").replace("[", " ").replace("]", " ").split()
    try:
        values = np.array(tokens, dtype=np.float64)
    except ValueError:
        split: list[str] = []
        for position, token in enumerate(tokens, start=1):
            try:
                float(token)
                split.append(token)
                continue
            except ValueError:
                pieces = _stream_reals(token)
            if pieces is None:
                raise FieldValueError(
                    f"value {position} ({token!r}) is not a number", hint="write plain decimal numbers"
                ) from None
            split.extend(pieces)
        tokens = split
        values = np.array(tokens, dtype=np.float64)
    if values.size and not np.isfinite(values).all():
        bad = int(np.flatnonzero(~np.isfinite(values))[0])
        raise FieldValueError(
            f"value {bad + 1} ({tokens[bad]}) is not finite",
            code="E206",
            hint="nan and inf are not valid scene values",
        )
    return values


# SOFA expands "A-B" and "A-B-step" in integer lists; more values than this is not an index list.
_MAX_RANGE_VALUES = 10_000_000


def _integers(token: str) -> list[int]:
    """One word of an integer list as SOFA's vector<int>::read reads it: "7", or the inclusive
    range "A-B" (descending when B < A), or "A-B-step" (a step against the direction swaps A, B)."""
    hyphen = token.find("-", 1)
    if hyphen < 0:
        return [int(token)]
    second = token.find("-", hyphen + 2)
    first = int(token[:hyphen])
    if second < 0:
        last = int(token[hyphen + 1 :])
        step = 1 if first < last else -1
    else:
        last, step = int(token[hyphen + 1 : second]), int(token[second + 1 :])
        if step == 0:
            step = 1 if first < last else -1
        if (last - first) * step < 0:
            first, last = last, first
    if abs(last - first) // abs(step) >= _MAX_RANGE_VALUES:
        raise OverflowError(token)
    return list(range(first, last + (1 if step > 0 else -1), step))


def parse_ints(text: str, *, nonnegative: bool = True) -> np.ndarray:
    tokens = text.replace(",", " ").replace("[", " ").replace("]", " ").split()
    try:
        values = np.array([i for t in tokens for i in _integers(t)], dtype=np.int64)
    except (ValueError, OverflowError):
        for position, token in enumerate(tokens, start=1):
            try:
                numbers = _integers(token)
            except ValueError:
                raise FieldValueError(
                    f"value {position} ({token!r}) is not an integer or a range A-B",
                    hint="indices are whole numbers; SOFA reads 0-50 as 0 to 50, 0-50-2 as every other one",
                ) from None
            except OverflowError:
                raise FieldValueError(
                    f"value {position} ({token!r}) is a range of {_MAX_RANGE_VALUES:,} values or more",
                    hint="index lists are far shorter",
                ) from None
            if any(not -(2**63) <= number < 2**63 for number in numbers):
                shown = token if len(token) <= 24 else token[:21] + "..."
                raise FieldValueError(
                    f"value {position} ({shown}) does not fit in a 64-bit integer",
                    hint="indices and counts are far smaller",
                ) from None
        raise
    if nonnegative and values.size and (values < 0).any():
        bad = int(np.flatnonzero(values < 0)[0])
        raise FieldValueError(f"index {values[bad]} (value {bad + 1}) is negative", code="E218")
    return values


@dataclass(frozen=True)
class FieldType:
    """Base: a single string value."""

    kind = "string"

    def parse(self, text: str) -> Any:
        return text

    def format(self, value: Any) -> str:
        if isinstance(value, np.ndarray):
            # ravel: a 0-d array (a scalar such as dt) or a 2-D one formats as a flat list of numbers.
            numbers = value.ravel().tolist()
            return " ".join(_format_real(x) if value.dtype.kind == "f" else str(x) for x in numbers)
        if isinstance(value, bool):
            return "1" if value else "0"
        if isinstance(value, float):
            return _format_real(value)
        if isinstance(value, (list, tuple)):
            return " ".join(self.format(v) for v in value)
        return str(value)

    def check_count(self, value: Any, datatype: DataType | None) -> str | None:
        return None

    def describe(self) -> str:
        return self.kind


@dataclass(frozen=True)
class Text(FieldType):
    kind = "string"


@dataclass(frozen=True)
class Real(FieldType):
    kind = "real"

    def parse(self, text: str) -> float:
        values = parse_reals(text)
        if values.size != 1:
            raise FieldValueError(f"expected one number, got {values.size}", code="E205")
        return float(values[0])


# The integer `istream >> int` reads at the start of a text (white space skipped).
_STREAM_INT = re.compile(r"\s*[+-]?\d+")
# What strtof / strtol accept in full: leading white space, then one decimal number, nothing after.
_STRTOF = re.compile(r"\s*[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?")
_STRTOL = re.compile(r"\s*[+-]?\d+")


@dataclass(frozen=True)
class AttributeNumber(FieldType):
    """An attribute a component's parse() reads with BaseObjectDescription::getAttributeAsFloat
    (strtof: a single-precision float) or getAttributeAsInt (strtol), not a Data: the whole text
    must be one number, else SOFA logs that it cannot parse it and uses the default. So a value
    that does not parse is a warning (W225) and the field keeps its default. ``flag``: an integer
    read as ``!= 0`` (VisualModelImpl's normals, castshadow)."""

    kind = "real"
    integer: bool = False
    flag: bool = False

    def parse(self, text: str) -> Any:
        pattern = _STRTOL if self.integer or self.flag else _STRTOF
        if pattern.fullmatch(text) is None:
            what, reader = ("an integer", "Int") if pattern is _STRTOL else ("one number", "Float")
            raise FieldValueError(
                f"SOFA reads this attribute as {what} (getAttributeAs{reader}), "
                f"cannot read {text.strip()[:40]!r} and uses its default",
                code="W225",
                hint="write one number, or remove the attribute",
            )
        if self.integer or self.flag:
            number = int(text)
            return number != 0 if self.flag else number
        value = float(np.float32(float(text)))
        if not math.isfinite(value):
            raise FieldValueError(
                f"{text.strip()} is not finite in single precision (SOFA reads it as a float)", code="E206"
            )
        return value


@dataclass(frozen=True)
class Int(FieldType):
    kind = "int"
    nonnegative: bool = False

    def parse(self, text: str) -> int:
        try:
            values = parse_ints(text, nonnegative=self.nonnegative)
        except FieldValueError:
            values = None
        if values is not None and values.size == 1:
            return int(values[0])
        # Data<int>::read is `istream >> int`: the integer the text starts with, the rest unread
        # (CGLinearSolver iterations="1e4" is 1 iteration, Component/Mapping/NonLinear/SquareMapping.scn).
        prefix = _STREAM_INT.match(text)
        if prefix is None or (self.nonnegative and int(prefix.group()) < 0):
            if values is None:
                return int(parse_ints(text, nonnegative=self.nonnegative)[0])  # its diagnostic
            raise FieldValueError(f"expected one integer, got {values.size}", code="E205")
        number = int(prefix.group())
        raise FieldValueError(
            f"SOFA reads an integer from the start of {text.strip()[:40]!r}: {number}, and ignores the rest",
            code="W225",
            hint=f"write the integer alone (SOFA's value here: {number})",
            value=number,
        )


_TRUE = {"1", "true", "yes", "on"}
_FALSE = {"0", "false", "no", "off"}


@dataclass(frozen=True)
class Bool(FieldType):
    kind = "bool"

    def parse(self, text: str) -> bool:
        word = text.strip().lower()
        if word in _TRUE:
            return True
        if word in _FALSE:
            return False
        raise FieldValueError(f"{text.strip()!r} is not a boolean", hint="write 0/1 or false/true")


@dataclass(frozen=True)
class Enum(FieldType):
    kind = "enum"
    values: tuple[str, ...] = ()
    case_sensitive: bool = False

    def parse(self, text: str) -> str:
        word = text.strip()
        for value in self.values:
            if word == value or (not self.case_sensitive and word.lower() == value.lower()):
                return value
        raise FieldValueError(
            f"{word!r} is not one of {', '.join(self.values)}", hint=f"use one of: {', '.join(self.values)}"
        )

    def describe(self) -> str:
        return "enum(" + "|".join(self.values) + ")"


@dataclass(frozen=True)
class Options(Enum):
    """SOFA's OptionsGroup: one of ``values``, written by name or by its 0-based index."""

    kind = "options"

    def parse(self, text: str) -> str:
        word = text.strip()
        if word.isdigit() and int(word) < len(self.values):
            return self.values[int(word)]
        return super().parse(text)


@dataclass(frozen=True)
class Reals(FieldType):
    """A vector of reals: fixed ``size``, or any count that is a multiple of ``multiple``."""

    kind = "reals"
    size: int | None = None
    multiple: int = 1
    allow_scalar: bool = False  # one value broadcast to the whole vector is accepted

    def parse(self, text: str) -> np.ndarray:
        values = parse_reals(text)
        broadcast = self.allow_scalar and values.size == 1
        if self.size is not None and values.size != self.size and not broadcast:
            raise FieldValueError(f"expected {self.size} numbers, got {values.size}", code="E205")
        if self.multiple > 1 and values.size % self.multiple:
            raise FieldValueError(
                f"expected a multiple of {self.multiple} numbers, got {values.size}", code="E205"
            )
        return values

    def describe(self) -> str:
        return f"reals[{self.size}]" if self.size else "reals"


@dataclass(frozen=True)
class Ints(FieldType):
    """A list of non-negative integers (indices, element connectivity)."""

    kind = "indices"
    multiple: int = 1

    def parse(self, text: str) -> np.ndarray:
        values = parse_ints(text)
        if self.multiple > 1 and values.size % self.multiple:
            raise FieldValueError(
                f"expected a multiple of {self.multiple} indices, got {values.size}", code="E205"
            )
        return values


@dataclass(frozen=True)
class IntVector(FieldType):
    """A fixed-size vector of integers (grid resolutions ``n``, index ranges ``localRange``)."""

    kind = "ints"
    size: int = 3
    nonnegative: bool = False

    def parse(self, text: str) -> np.ndarray:
        values = parse_ints(text, nonnegative=self.nonnegative)
        if values.size != self.size:
            raise FieldValueError(f"expected {self.size} integers, got {values.size}", code="E205")
        return values

    def describe(self) -> str:
        return f"ints[{self.size}]"


@dataclass(frozen=True)
class Bools(FieldType):
    """A list of booleans written as 0/1 (or true/false) words: direction masks, per-spring flags."""

    kind = "bools"
    size: int | None = None

    def parse(self, text: str) -> np.ndarray:
        words = text.replace(",", " ").replace("[", " ").replace("]", " ").split()
        values = []
        for position, word in enumerate(words, start=1):
            lowered = word.lower()
            if lowered in _TRUE:
                values.append(True)
            elif lowered in _FALSE:
                values.append(False)
            else:
                raise FieldValueError(f"value {position} ({word!r}) is not a boolean", hint="write 0 or 1")
        if self.size is not None and len(values) != self.size:
            raise FieldValueError(f"expected {self.size} flags, got {len(values)}", code="E205")
        return np.array(values, dtype=bool)

    def format(self, value: Any) -> str:
        return " ".join("1" if bool(v) else "0" for v in np.asarray(value).ravel().tolist())

    def describe(self) -> str:
        return f"bools[{self.size}]" if self.size else "bools"


@dataclass(frozen=True)
class Coords(FieldType):
    """Per-DOF vectors of the component's DataType: positions (Coord) or velocities/forces (Deriv)."""

    kind = "coords"
    deriv: bool = False
    allow_single: bool = False  # one value replicated to every DOF is accepted

    def parse(self, text: str) -> np.ndarray:
        return parse_reals(text)

    def unit(self, datatype: DataType) -> int:
        return datatype.deriv_size if self.deriv else datatype.coord_size

    def check_count(self, value: Any, datatype: DataType | None) -> str | None:
        if datatype is None or not isinstance(value, np.ndarray):
            return None
        unit = self.unit(datatype)
        if value.size % unit:
            what = "Deriv" if self.deriv else "Coord"
            return f"{value.size} numbers is not a multiple of {unit}, the size of one {datatype.name} {what}"
        return None

    def describe(self) -> str:
        return "deriv[]" if self.deriv else "coord[]"


@dataclass(frozen=True)
class Springs(FieldType):
    """Spring list ``i j ks kd L0`` per spring."""

    kind = "springs"

    def parse(self, text: str) -> np.ndarray:
        values = parse_reals(text)
        if values.size % 5:
            raise FieldValueError(
                f"{values.size} numbers is not a multiple of 5",
                code="E205",
                hint="each spring is 'i j stiffness damping restLength'",
            )
        springs = values.reshape(-1, 5)
        ends = springs[:, :2]
        if (ends != np.floor(ends)).any() or (ends < 0).any():
            row = int(np.flatnonzero(((ends != np.floor(ends)) | (ends < 0)).any(axis=1))[0])
            raise FieldValueError(
                f"spring {row}: end indices {ends[row, 0]:g} {ends[row, 1]:g} are not non-negative integers"
            )
        return springs

    def ends(self, value: Any) -> np.ndarray:
        return np.asarray(value).reshape(-1, 5)[:, :2]

    def format(self, value: Any) -> str:
        rows = np.asarray(value).reshape(-1, 5)
        return "  ".join(f"{int(r[0])} {int(r[1])} {' '.join(_format_real(x) for x in r[2:])}" for r in rows)


# JointSpring's stream form, one row per spring (JointSprings.parse): the columns.
JOINT_SPRING_COLUMNS = (
    "m1", "m2",
    *(f"free{i}" for i in range(6)),
    "softStiffnessTrans", "hardStiffnessTrans", "softStiffnessRot", "hardStiffnessRot",
    "blocStiffnessRot", "kd",
    *(f"limit{i}" for i in range(6)),
    "initTrans0", "initTrans1", "initTrans2",
    "initRot0", "initRot1", "initRot2", "initRot3",
    "needToInitialize",
)  # fmt: skip
_JOINT_KEYWORDS = {
    "FREE_AXIS": "6 flags (0/1): translations x y z, rotations x y z free",
    "KS_T": "2 numbers: soft and hard translation stiffness",
    "KS_R": "2 numbers: soft and hard rotation stiffness",
    "KS_B": "1 number: stiffness beyond the angle limits",
    "KD": "1 number: damping",
    "R_LIM_X": "2 numbers: angle limits about x",
    "R_LIM_Y": "2 numbers: angle limits about y",
    "R_LIM_Z": "2 numbers: angle limits about z",
    "REST_T": "3 numbers: rest translation",
    "REST_R": "4 numbers: rest orientation (quaternion x y z w)",
}


@dataclass(frozen=True)
class JointSprings(FieldType):
    """JointSpringForceField's ``spring``: ``BEGIN_SPRING m1 m2 [KEYWORD values]... END_SPRING`` per
    spring, read as SOFA's ``operator>>(istream&, JointSpring&)`` inside ``vector<T>::read``. That
    reader keeps one JointSpring for the whole list, so the stiffnesses and the damping (KS_T, KS_R,
    KD) a spring leaves out are the previous spring's (first: 0 10000, 0 10000, 0); the free axes,
    limits, rest offset and KS_B start afresh for each. KS_B 0 (or none) is KS_R's hard / 100; an
    axis whose two limits are equal is not free. ``needToInitialize`` is SOFA's flag, set when
    REST_T is given: bwdInit then replaces REST_T and REST_R by the initial relative placement."""

    kind = "joint springs"

    def parse(self, text: str) -> np.ndarray:
        tokens = text.split()
        position = 0

        def word() -> str:
            nonlocal position
            if position >= len(tokens):
                raise FieldValueError(
                    "the list ends inside a spring (no END_SPRING)",
                    hint="end each spring with END_SPRING",
                )
            position += 1
            return tokens[position - 1]

        def reals(count: int, keyword: str) -> list[float]:
            values: list[float] = []
            while len(values) < count:
                token = word()
                pieces = _stream_reals(token)
                if token in _JOINT_KEYWORDS or token == "END_SPRING" or not pieces:
                    raise FieldValueError(
                        f"spring {len(rows)}: {keyword} needs {_JOINT_KEYWORDS[keyword]}, got {token!r}",
                        hint=f"write {keyword} followed by {count} number{'s' if count > 1 else ''}",
                    )
                values.extend(float(piece) for piece in pieces)
            if len(values) > count:  # a word such as 0-1 read as two numbers: give the rest back
                raise FieldValueError(
                    f"spring {len(rows)}: {keyword} takes {count} numbers",
                    hint="separate the numbers with spaces",
                )
            return values

        rows: list[list[float]] = []
        kept = {"ks_t": [0.0, 10000.0], "ks_r": [0.0, 10000.0], "kd": 0.0}
        while position < len(tokens):
            start = word()
            if start != "BEGIN_SPRING":
                raise FieldValueError(
                    f"spring {len(rows)} starts with {start!r}, not BEGIN_SPRING",
                    hint="each spring is BEGIN_SPRING m1 m2 [FREE_AXIS ..., KS_T ..., ...] END_SPRING",
                )
            ends: list[float] = []
            for _ in range(2):
                token = word()
                if not token.isdigit():
                    raise FieldValueError(
                        f"spring {len(rows)}: DOF index {token!r} is not a non-negative integer",
                        hint="BEGIN_SPRING is followed by the indices of the two rigid DOFs",
                    )
                ends.append(float(int(token)))
            free = [0.0, 0.0, 0.0, 1.0, 1.0, 1.0]
            limits = [-100000.0, 100000.0, -100000.0, 100000.0, -100000.0, 100000.0]
            rest_t, rest_r, bloc, found = [0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0], 0.0, False
            keyword = word()
            while keyword != "END_SPRING":
                if keyword == "FREE_AXIS":
                    flags = [word() for _ in range(6)]
                    if any(f not in ("0", "1") for f in flags):
                        raise FieldValueError(
                            f"spring {len(rows)}: FREE_AXIS {' '.join(flags)} is not six 0/1 flags",
                            hint="FREE_AXIS tx ty tz rx ry rz, each 0 (blocked) or 1 (free)",
                        )
                    free = [float(f) for f in flags]
                elif keyword == "KS_T":
                    kept["ks_t"] = reals(2, keyword)
                elif keyword == "KS_R":
                    kept["ks_r"] = reals(2, keyword)
                elif keyword == "KS_B":
                    bloc = reals(1, keyword)[0]
                elif keyword == "KD":
                    kept["kd"] = reals(1, keyword)[0]
                elif keyword in ("R_LIM_X", "R_LIM_Y", "R_LIM_Z"):
                    axis = "XYZ".index(keyword[-1])
                    limits[2 * axis : 2 * axis + 2] = reals(2, keyword)
                elif keyword == "REST_T":
                    rest_t, found = reals(3, keyword), True
                elif keyword == "REST_R":
                    rest_r = reals(4, keyword)
                else:
                    raise FieldValueError(
                        f"spring {len(rows)}: unknown attribute {keyword!r} (SOFA stops reading there)",
                        hint="the attributes are " + ", ".join(_JOINT_KEYWORDS) + "; end with END_SPRING",
                    )
                keyword = word()
            hard_r = kept["ks_r"][1]
            if bloc == 0.0:
                bloc = hard_r / 100
            for axis in range(3):
                if limits[2 * axis] == limits[2 * axis + 1]:
                    free[3 + axis] = 0.0
            rows.append(
                [
                    *ends,
                    *free,
                    *kept["ks_t"],
                    *kept["ks_r"],
                    bloc,
                    float(kept["kd"]),
                    *limits,
                    *rest_t,
                    *rest_r,
                    1.0 if found else 0.0,
                ]
            )
        values = np.array(rows, dtype=np.float64).reshape(-1, len(JOINT_SPRING_COLUMNS))
        if values.size and not np.isfinite(values).all():
            raise FieldValueError(
                "a number is not finite", code="E206", hint="nan and inf are not valid scene values"
            )
        return values

    def ends(self, value: Any) -> np.ndarray:
        return np.asarray(value).reshape(-1, len(JOINT_SPRING_COLUMNS))[:, :2]

    def format(self, value: Any) -> str:
        parts = []
        for row in np.asarray(value).reshape(-1, len(JOINT_SPRING_COLUMNS)):
            free = " ".join(str(int(f)) for f in row[2:8])
            numbers = [_format_real(x) for x in row[8:]]
            text = f"BEGIN_SPRING {int(row[0])} {int(row[1])} FREE_AXIS {free} KS_T {numbers[0]} {numbers[1]}"
            text += f" KS_R {numbers[2]} {numbers[3]} KS_B {numbers[4]} KD {numbers[5]}"
            text += f" R_LIM_X {numbers[6]} {numbers[7]} R_LIM_Y {numbers[8]} {numbers[9]}"
            text += f" R_LIM_Z {numbers[10]} {numbers[11]}"
            if row[-1]:
                text += f" REST_T {' '.join(numbers[12:15])}"
            text += f" REST_R {' '.join(numbers[15:19])} END_SPRING"
            parts.append(text)
        return "\n".join(parts)

    def describe(self) -> str:
        return "joint springs (BEGIN_SPRING m1 m2 ... END_SPRING)"


@dataclass(frozen=True)
class MassValue(FieldType):
    """One DOF's mass: a real for Vec types, ``m volume I[9]`` (or just ``m``) for Rigid3d."""

    kind = "mass"

    def parse(self, text: str) -> np.ndarray:
        return parse_reals(text)

    def check_count(self, value: Any, datatype: DataType | None) -> str | None:
        if datatype is None or not isinstance(value, np.ndarray):
            return None
        if value.size not in datatype.mass_sizes:
            sizes = " or ".join(str(s) for s in datatype.mass_sizes)
            return f"a {datatype.name} mass has {sizes} numbers, got {value.size}"
        return None


@dataclass(frozen=True)
class Link(FieldType):
    """A link to another object (``@../dofs``): ``target`` names the category expected.
    ``optional``: the component works without it, and SOFA only warns when the path finds nothing
    (a warning here too, W233), else a broken link stops the component in SOFA (E213)."""

    kind = "link"
    target: str = "object"
    optional: bool = False

    def parse(self, text: str) -> str:
        return text.strip()


@dataclass(frozen=True)
class LinkList(Link):
    """Several links in one attribute, separated by whitespace (``input="@../a @../b"``)."""

    kind = "links"

    def parse(self, text: str) -> tuple[str, ...]:  # type: ignore[override]
        return tuple(text.split())


@dataclass(frozen=True)
class SofaData(FieldType):
    """A Data known only from SOFA's source (registry/catalogue.py): its C++ type, read as text."""

    kind = "sofa"
    cpp_type: str = ""

    def parse(self, text: str) -> str:
        return text.strip()

    def describe(self) -> str:
        return self.cpp_type or self.kind


@dataclass(frozen=True)
class FileName(FieldType):
    """A data file path; ``output`` files are written by SOFA, so they need not exist."""

    kind = "file"
    output: bool = False

    def parse(self, text: str) -> str:
        return text.strip()


@dataclass(frozen=True)
class Words(FieldType):
    """Whitespace-separated words (display flags, plugin names, tags)."""

    kind = "words"

    def parse(self, text: str) -> tuple[str, ...]:
        return tuple(text.split())


COLOR_NAMES: dict[str, tuple[float, float, float, float]] = {
    "white": (1, 1, 1, 1),
    "black": (0, 0, 0, 1),
    "red": (1, 0, 0, 1),
    "green": (0, 1, 0, 1),
    "blue": (0, 0, 1, 1),
    "cyan": (0, 1, 1, 1),
    "magenta": (1, 0, 1, 1),
    "yellow": (1, 1, 0, 1),
    "gray": (0.5, 0.5, 0.5, 1),
    "grey": (0.5, 0.5, 0.5, 1),
    "orange": (1, 0.5, 0, 1),
    "purple": (0.5, 0, 0.5, 1),
    "pink": (1, 0.75, 0.8, 1),
    "brown": (0.6, 0.4, 0.2, 1),
    "darkgray": (0.25, 0.25, 0.25, 1),
    "lightgray": (0.75, 0.75, 0.75, 1),
}


@dataclass(frozen=True)
class Color(FieldType):
    """A color: a name, ``#rrggbb[aa]``, or 3/4 numbers in [0, 1]."""

    kind = "color"

    def parse(self, text: str) -> tuple[float, float, float, float]:
        word = text.strip()
        if word.lower() in COLOR_NAMES:
            return COLOR_NAMES[word.lower()]
        if word.startswith("#") and len(word) in (7, 9):
            try:
                channels = [int(word[i : i + 2], 16) / 255 for i in range(1, len(word), 2)]
            except ValueError:
                raise FieldValueError(f"{word!r} is not a color") from None
            return tuple([*channels, 1.0][:4])  # type: ignore[return-value]
        values = parse_reals(word)
        if values.size not in (3, 4):
            raise FieldValueError(
                f"{word!r} is not a color", hint="use a name (red), #rrggbb, or 'r g b a' in [0, 1]"
            )
        rgba = [*values.tolist(), 1.0][:4]
        return tuple(rgba)  # type: ignore[return-value]


def is_finite_number(x: float) -> bool:
    return math.isfinite(x)
