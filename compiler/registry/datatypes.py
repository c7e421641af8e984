"""SOFA DataTypes (Vec1d ... Rigid3d): sizes of their Coord and Deriv, and template name aliases."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class DataType:
    name: str  # canonical SOFA name, e.g. "Rigid3d"
    coord_size: int  # scalars per position
    deriv_size: int  # scalars per velocity / force
    spatial_dim: int  # dimension of the space the DOF lives in
    rigid: bool = False

    @property
    def mass_sizes(self) -> tuple[int, ...]:
        """Accepted scalar counts of one ``vertexMass`` value (Rigid: m, volume, inertia matrix)."""
        if not self.rigid:
            return (1,)
        inertia = 9 if self.spatial_dim == 3 else 1
        return (1, 2 + inertia)


DATATYPES: dict[str, DataType] = {
    dt.name: dt
    for dt in (
        DataType("Vec1d", 1, 1, 1),
        DataType("Vec2d", 2, 2, 2),
        DataType("Vec3d", 3, 3, 3),
        DataType("Vec6d", 6, 6, 6),
        DataType("Rigid2d", 3, 3, 2, rigid=True),
        DataType("Rigid3d", 7, 6, 3, rigid=True),
    )
}

# Template spellings SOFA accepts for the DataTypes above. The value says whether SOFA would
# warn about the spelling (float variants and bare "Rigid" are accepted with a warning).
_TEMPLATE_ALIASES: dict[str, tuple[str, bool]] = {}
for _name in DATATYPES:
    _base = _name[:-1]
    _TEMPLATE_ALIASES[_name] = (_name, False)
    _TEMPLATE_ALIASES[_base] = (_name, False)
    _TEMPLATE_ALIASES[_base + "f"] = (_name, True)
_TEMPLATE_ALIASES["Rigid"] = ("Rigid3d", True)


def canonical_datatype(spelling: str) -> tuple[str, bool] | None:
    """Canonical DataType name for a template spelling, and whether SOFA warns about it."""
    return _TEMPLATE_ALIASES.get(spelling.strip())


def split_template(text: str) -> list[str]:
    """Split ``"Rigid3d,Vec3d"`` into its parts (SOFA separates template arguments by commas)."""
    return [part.strip() for part in text.split(",") if part.strip()]
