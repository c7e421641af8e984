"""One rule for every path a user types: states (``sim["..."]``), parameters (``sim.param``),
outputs (``sim.output``), sweep keys (``--param``) and record keys (``--record``).

A path is written as sofac prints it (``/pendulum/spring.stiffness``, ``/.dt``), or without its
leading slash (``pendulum/spring.stiffness``, ``.dt``), or by its end when that end is unique in
the scene (``spring.stiffness``, ``dofs``): whole segments after a slash, never part of a name.
A miss names the closest paths (did you mean ...?) and lists them all.
"""

from __future__ import annotations

from collections.abc import Iterable


class UnknownPath(KeyError):
    """A path that names nothing (or more than one thing) of the scene; a KeyError, so that code
    looking keys up the usual way still catches it."""

    def __init__(self, message: str, text: object) -> None:
        super().__init__(message)
        self.message = message
        self.text = text

    def __str__(self) -> str:  # KeyError would print the message's repr
        return self.message


def matches(text: str, keys: Iterable[str]) -> list[str]:
    """The keys ``text`` names under the rule above (one, or several when it is ambiguous)."""
    keys = list(keys)
    rooted = "/" + text.strip().lstrip("/")
    exact = [k for k in keys if k in (text, rooted)]
    if exact:
        return exact[:1]
    return [k for k in keys if k.endswith(rooted)]


def resolve(text: object, keys: Iterable[str], what: str) -> str:
    """The one key of ``keys`` that ``text`` names; raises UnknownPath (``what``: "MechanicalObject",
    "parameter"...) with the closest keys and the whole list otherwise, TypeError for a non-string."""
    keys = list(keys)
    if not isinstance(text, str):
        example = f", such as {keys[0]!r}" if keys else ""
        raise TypeError(f"a {what} is named by its path, a string{example}; got {type(text).__name__}")
    found = matches(text, keys)
    if len(found) == 1:
        return found[0]
    listing = ", ".join(keys) or "none"
    if found:
        raise UnknownPath(
            f"{text!r} is ambiguous: it names the {what}s {', '.join(found)}; give a longer path", text
        )
    import difflib  # only a miss needs it

    close = difflib.get_close_matches("/" + text.strip().lstrip("/"), keys, n=3, cutoff=0.6)
    if not close:  # a short form: compare the last segments
        ends = {k.rsplit("/", 1)[-1]: k for k in keys}
        close = [ends[e] for e in difflib.get_close_matches(text.rsplit("/", 1)[-1], list(ends), n=3)]
    guess = f"did you mean {' or '.join(repr(c) for c in close)}? " if close else ""
    raise UnknownPath(f"no {what} {text!r}; {guess}the scene has: {listing}", text)
