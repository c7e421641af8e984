"""Safe, SOFA-tolerant XML reading: one hardened lxml parser plus a small repairing tokenizer.

SOFA reads scenes with tinyxml2, which accepts a few things conforming XML parsers reject. The
tokenizer here walks the raw text once to (a) refuse DTDs/entities before libxml2 ever sees them,
(b) cap the nesting depth, (c) record the line of every start tag and of every attribute (lxml only
knows the line where a start tag *ends*), and (d) prepare the repairs SOFA would implicitly make.
The repairs are used only if the strict parse fails, and never add or remove a newline, so every
line number stays that of the user's file.
"""

from __future__ import annotations

import codecs
import re
import threading
from dataclasses import dataclass, field
from typing import Any

from lxml import etree

#: Deepest element nesting accepted (libxml2 without huge_tree stops at 256 anyway).
MAX_DEPTH = 200

_XINCLUDE_NS = "http://www.w3.org/2001/XInclude"
_XML_NS = "http://www.w3.org/XML/1998/namespace"

_WS = " \t\r\n"
_WS_RE = re.compile(r"[ \t\r\n]*")
# Permissive names (tinyxml2 is permissive too); lxml validates them properly afterwards.
_NAME_RE = re.compile(r"[^ \t\r\n/>=\"'<&!?][^ \t\r\n/>=\"'<&]*")
_ATTR_NAME_RE = re.compile(r"[^ \t\r\n/>=\"'<&]+")
# The only references tinyxml2 decodes; any other '&' is literal text for SOFA.
_REF_RE = re.compile(r"&(?:amp|lt|gt|quot|apos|#[0-9]+|#x[0-9a-fA-F]+);")
_XML_DECL_RE = re.compile(r"<\?xml(?=[ \t\r\n?])")
_FORBIDDEN_RE = re.compile(r"<!(DOCTYPE|ENTITY|ELEMENT|ATTLIST|NOTATION)", re.IGNORECASE)
_LXML_LOCATION_RE = re.compile(r",? line \d+, column \d+$")
_ENCODING_DECL_RE = re.compile(
    rb"<\?xml[^>]{0,200}?encoding[ \t\r\n]*=[ \t\r\n]*[\"']([A-Za-z0-9._-]{1,40})[\"']"
)

_BOMS: tuple[tuple[bytes, str], ...] = (
    (codecs.BOM_UTF32_LE, "utf-32-le"),  # before UTF-16 LE: it starts with the same two bytes
    (codecs.BOM_UTF32_BE, "utf-32-be"),
    (codecs.BOM_UTF8, "utf-8"),
    (codecs.BOM_UTF16_LE, "utf-16-le"),
    (codecs.BOM_UTF16_BE, "utf-16-be"),
)


class XMLReadError(Exception):
    """The text cannot be accepted: ``code`` is E101 (malformed), E102 (forbidden) or E104 (depth)."""

    def __init__(self, code: str, line: int, message: str, hint: str = "") -> None:
        super().__init__(message)
        self.code = code
        self.line = line
        self.message = message
        self.hint = hint


@dataclass
class StartTag:
    """A start tag as written: its name, the line of its '<' and the line of each attribute."""

    name: str
    line: int
    attr_lines: dict[str, int] = field(default_factory=dict)


@dataclass(frozen=True)
class Repair:
    line: int
    what: str


@dataclass
class XMLDocument:
    root: Any  # etree._Element
    # Start-tag information for each element (absent if the tokenizer and lxml disagreed).
    tags: dict[Any, StartTag]
    repairs: list[Repair]

    def line_of(self, element: Any) -> int:
        tag = self.tags.get(element)
        return tag.line if tag else int(element.sourceline or 0)

    def attribute_line(self, element: Any, name: str) -> int:
        tag = self.tags.get(element)
        if tag is None:
            return int(element.sourceline or 0)
        return tag.attr_lines.get(name, tag.line)


# --- the parser ----------------------------------------------------------------------------------

_local = threading.local()


def hardened_parser() -> etree.XMLParser:
    """The one parser configuration sofac uses (one instance per thread: lxml parsers are not
    thread-safe). No entity expansion, no DTD, no network, no size-limit lifting, no recovery."""
    parser = getattr(_local, "parser", None)
    if parser is None:
        parser = etree.XMLParser(
            resolve_entities=False,
            no_network=True,
            load_dtd=False,
            dtd_validation=False,
            huge_tree=False,
            remove_pis=True,
            remove_comments=True,
            recover=False,
            attribute_defaults=False,
        )
        _local.parser = parser
    return parser


# --- decoding ------------------------------------------------------------------------------------


def decode(data: bytes) -> tuple[str, Repair | None]:
    """Bytes to text the way libxml2 would pick the encoding (BOM, then declaration, else UTF-8).

    Undecodable bytes (e.g. Latin-1 accents in a comment; tinyxml2 does not care) are returned as a
    Latin-1 reading plus the repair that says so; the strict parse treats that as a failure.
    """
    codec = "utf-8"
    body = data
    for bom, name in _BOMS:
        if data.startswith(bom):
            codec, body = name, data[len(bom) :]
            break
    else:
        if data.startswith(b"<\x00"):
            codec = "utf-16-le"
        elif data.startswith(b"\x00<"):
            codec = "utf-16-be"
        else:
            match = _ENCODING_DECL_RE.match(data)
            if match:
                declared = match.group(1).decode("ascii").lower()
                try:
                    info = codecs.lookup(declared)
                except LookupError:
                    info = None
                # A declaration readable as ASCII cannot be UTF-16/32; keep ASCII-compatible codecs.
                if (
                    info is not None
                    and getattr(info, "_is_text_encoding", True)
                    and not info.name.startswith(("utf-16", "utf-32"))
                ):
                    codec = info.name
    try:
        return body.decode(codec), None
    except (UnicodeDecodeError, LookupError) as exc:
        start = exc.start if isinstance(exc, UnicodeDecodeError) else 0
        line = body.count(b"\n", 0, start) + 1
        return body.decode("latin-1"), Repair(line, f"bytes that are not valid {codec} were read as Latin-1")


def _to_utf8(text: str) -> bytes:
    """UTF-8 bytes for lxml, without a leading XML declaration (its encoding no longer applies)."""
    if text.startswith("\ufeff"):
        text = text[1:]
    if _XML_DECL_RE.match(text):
        end = text.find("?>")
        if end >= 0:
            text = "\n" * text.count("\n", 0, end) + text[end + 2 :]
    try:
        return text.encode("utf-8")
    except UnicodeEncodeError as exc:
        line = text.count("\n", 0, exc.start) + 1
        raise XMLReadError("E101", line, "text contains characters that cannot be encoded") from None


# --- the tokenizer -------------------------------------------------------------------------------


@dataclass
class _Scan:
    tags: list[StartTag] = field(default_factory=list)
    repairs: list[Repair] = field(default_factory=list)
    edits: list[tuple[int, int, str]] = field(default_factory=list)
    forbidden: tuple[int, str] | None = None
    too_deep: int | None = None
    complete: bool = True

    def apply(self, text: str) -> str:
        if not self.edits:
            return text
        pieces: list[str] = []
        last = 0
        for start, end, replacement in self.edits:
            pieces.append(text[last:start])
            pieces.append(replacement)
            last = end
        pieces.append(text[last:])
        return "".join(pieces)


class _Tokenizer:
    """One left-to-right pass with ``str.find`` (fast even on megabyte-long attribute values)."""

    def __init__(self, text: str, max_depth: int) -> None:
        self.text = text
        self.n = len(text)
        self.max_depth = max_depth
        self.scan = _Scan()
        self._line = 1
        self._line_pos = 0
        self.root_name = ""
        self.root_closed_line = 0

    def line_at(self, pos: int) -> int:
        # Positions are only ever asked in increasing order, so counting is incremental.
        if pos > self._line_pos:
            self._line += self.text.count("\n", self._line_pos, pos)
            self._line_pos = pos
        return self._line

    def edit(self, start: int, end: int, replacement: str) -> None:
        self.scan.edits.append((start, end, replacement))

    def drop(self, start: int, end: int) -> None:
        """Remove text but keep its newlines, so later lines keep their numbers."""
        self.edit(start, end, "\n" * self.text.count("\n", start, end))

    def escape_in(self, start: int, end: int, what: str) -> None:
        """Escape bare '<' and '&' between start and end (an attribute value)."""
        lts = self._positions(start, end, "<")
        amps = [p for p in self._positions(start, end, "&") if not _REF_RE.match(self.text, p)]
        found: list[tuple[int, str]] = []
        if lts:
            found.append((lts[0], f"unescaped '<' in {what} (read as &lt;)"))
        if amps:
            found.append((amps[0], f"raw '&' in {what} (read as &amp;)"))
        for pos, message in sorted(found):  # in position order: line_at only moves forward
            self.scan.repairs.append(Repair(self.line_at(pos), message))
        for pos, replacement in sorted([(p, "&lt;") for p in lts] + [(p, "&amp;") for p in amps]):
            self.edit(pos, pos + 1, replacement)

    def _positions(self, start: int, end: int, char: str) -> list[int]:
        out: list[int] = []
        pos = self.text.find(char, start, end)
        while pos >= 0:
            out.append(pos)
            pos = self.text.find(char, pos + 1, end)
        return out

    def forbid(self, pos: int) -> None:
        match = _FORBIDDEN_RE.match(self.text, pos)
        keyword = match.group(1).upper() if match else "DOCTYPE"
        self.scan.forbidden = (self.line_at(pos), keyword)

    def run(self) -> _Scan:
        text, n = self.text, self.n
        depth = 0
        root_closed = False
        i = 0
        while i < n:
            j = text.find("<", i)
            end = n if j < 0 else j
            if root_closed:
                junk = self._first_non_ws(i, end)
                if junk >= 0:
                    self._junk(junk)
                    return self.scan
            elif end > i and text.find("&", i, end) >= 0:
                self._text_amps(i, end)
            if j < 0:
                break
            if text.startswith("<!--", j):
                k = text.find("-->", j + 4)
                if k < 0:
                    return self._bail(j)
                i = k + 3
                continue
            if text.startswith("<?", j):
                k = text.find("?>", j + 2)
                if k < 0:
                    return self._bail(j)
                if _XML_DECL_RE.match(text, j) and j != 0:
                    # libxml2 allows the declaration only as the very first thing; SOFA ignores it.
                    self.scan.repairs.append(
                        Repair(self.line_at(j), "XML declaration not at the start of the file (ignored)")
                    )
                    self.drop(j, k + 2)
                i = k + 2
                continue
            if _FORBIDDEN_RE.match(text, j):
                self.forbid(j)
                return self.scan
            if root_closed:
                self._junk(j)
                return self.scan
            if text.startswith("<![CDATA[", j):
                k = text.find("]]>", j + 9)
                if k < 0:
                    return self._bail(j)
                i = k + 3
                continue
            if text.startswith("<!", j):
                return self._bail(j)
            if text.startswith("</", j):
                k = text.find(">", j + 2)
                if k < 0:
                    return self._bail(j)
                depth -= 1
                if depth == 0:
                    root_closed = True
                    self.root_closed_line = self.line_at(j)
                elif depth < 0:
                    return self._bail(j)
                i = k + 1
                continue
            result = self._start_tag(j)
            if result is None:
                return self._bail(j)
            i, self_closing = result
            if not self_closing:
                depth += 1
                if depth > self.max_depth:
                    self.scan.too_deep = self.scan.tags[-1].line
                    return self.scan
            elif depth == 0:
                root_closed = True
                self.root_closed_line = self.scan.tags[-1].line
        return self.scan

    def _first_non_ws(self, start: int, end: int) -> int:
        m = _WS_RE.match(self.text, start, end)
        pos = m.end() if m else start
        return pos if pos < end else -1

    def _junk(self, pos: int) -> None:
        # tinyxml2 keeps parsing after the root and SOFA only uses the first root element: whatever
        # follows it (stray end tags, a second element, text) has no effect.
        self.scan.repairs.append(
            Repair(
                self.line_at(pos),
                f"content after the end of the root element <{self.root_name}> "
                f"(closed at line {self.root_closed_line}) ignored, as SOFA does",
            )
        )
        self.drop(pos, self.n)

    def _text_amps(self, start: int, end: int) -> None:
        text = self.text
        pos = text.find("&", start, end)
        reported = False
        while pos >= 0:
            if not _REF_RE.match(text, pos):
                if not reported:
                    self.scan.repairs.append(Repair(self.line_at(pos), "raw '&' in text (read as &amp;)"))
                    reported = True
                self.edit(pos, pos + 1, "&amp;")
            pos = text.find("&", pos + 1, end)

    def _bail(self, pos: int) -> _Scan:
        # Something the tokenizer does not understand: lxml will report it precisely. Still refuse
        # a DTD anywhere further on.
        self.scan.complete = False
        match = _FORBIDDEN_RE.search(self.text, pos)
        if match:
            self.forbid(match.start())
        return self.scan

    def _start_tag(self, j: int) -> tuple[int, bool] | None:
        """Scan one start tag at ``j``; returns (position after it, self-closing) or None."""
        text, n = self.text, self.n
        m = _NAME_RE.match(text, j + 1)
        if not m:
            return None
        tag = StartTag(m.group(0), self.line_at(j))
        if not self.scan.tags:
            self.root_name = tag.name
        self.scan.tags.append(tag)
        p = m.end()
        while True:
            p = _WS_RE.match(text, p).end()  # type: ignore[union-attr]
            if p >= n:
                return None
            c = text[p]
            if c == ">":
                return p + 1, False
            if c == "/" and text.startswith("/>", p):
                return p + 2, True
            am = _ATTR_NAME_RE.match(text, p)
            if not am:
                return None
            name = am.group(0)
            tag.attr_lines.setdefault(name, self.line_at(p))
            p = _WS_RE.match(text, am.end()).end()  # type: ignore[union-attr]
            if p >= n or text[p] != "=":
                return None
            p = _WS_RE.match(text, p + 1).end()  # type: ignore[union-attr]
            if p >= n or text[p] not in "\"'":
                return None
            quote = text[p]
            close = text.find(quote, p + 1)
            if close < 0:
                return None
            if text.find("<", p + 1, close) >= 0 or text.find("&", p + 1, close) >= 0:
                self.escape_in(p + 1, close, f"the value of attribute {name!r}")
            p = close + 1
            if p < n and text[p] not in _WS and text[p] not in "/>":
                self.scan.repairs.append(
                    Repair(
                        self.line_at(p),
                        f"no whitespace after attribute {name!r} before the next one (a space was assumed)",
                    )
                )
                self.edit(p, p, " ")


def scan(text: str, max_depth: int = MAX_DEPTH) -> _Scan:
    """Tokenize ``text`` once: start tags with lines, forbidden constructs, depth, repairs."""
    return _Tokenizer(text, max_depth).run()


# --- reading -------------------------------------------------------------------------------------


def _last_line(text: str) -> int:
    """The number of the file's last line (a final newline does not start another one)."""
    return max(1, text.count("\n") + (0 if text.endswith("\n") else 1))


def _syntax_error(exc: Exception, *, repaired: bool, last_line: int) -> XMLReadError:
    msg = str(getattr(exc, "msg", "") or exc)
    msg = _LXML_LOCATION_RE.sub("", msg.strip())
    # libxml2 reports an error at the end of the data on the line after a final newline.
    line = min(max(int(getattr(exc, "lineno", 0) or 0), 1), last_line)
    position = getattr(exc, "position", None)
    column = position[1] if isinstance(position, tuple) and len(position) == 2 else 0
    where = f" (column {column})" if column else ""
    if "Excessive depth" in msg:
        return XMLReadError(
            "E104", line, f"elements nested too deeply: {msg}", f"keep scene nesting under {MAX_DEPTH} levels"
        )
    if "entit" in msg.lower() and ("loop" in msg.lower() or "amplification" in msg.lower()):
        return XMLReadError("E102", line, f"entity expansion refused: {msg}")
    hint = "fix the XML at that line"
    if "too long" in msg.lower() or "huge" in msg.lower():
        hint = "move very large arrays into a mesh or data file (loaders read them without limit)"
    prefix = "not well-formed XML even after SOFA-style repairs" if repaired else "not well-formed XML"
    return XMLReadError("E101", line, f"{prefix}: {msg}{where}", hint)


def _parse_bytes(data: bytes) -> Any:
    return etree.fromstring(data, hardened_parser())


def _check_tree(root: Any) -> None:
    """Post-parse defence in depth: nothing DTD- or entity-related may have survived."""
    docinfo = root.getroottree().docinfo
    if docinfo.doctype or docinfo.internalDTD is not None or docinfo.externalDTD is not None:
        raise XMLReadError("E102", 1, "document type declarations (DOCTYPE) are not allowed in scenes")
    for entity in root.iter(etree.Entity):
        raise XMLReadError("E102", int(entity.sourceline or 0), "entity references are not allowed in scenes")
    for element in root.iter(f"{{{_XINCLUDE_NS}}}*"):
        raise XMLReadError(
            "E102",
            int(element.sourceline or 0),
            "XInclude elements are not allowed (use SOFA's <include href=...>)",
        )


def tag_name(element: Any) -> str:
    """An element's name as written (``prefix:local`` for namespaced names)."""
    tag = element.tag
    if not isinstance(tag, str):
        return ""
    if tag.startswith("{"):
        local = etree.QName(tag).localname
        return f"{element.prefix}:{local}" if element.prefix else local
    return tag


def attribute_name(key: str, element: Any) -> str:
    """An attribute's name as written (lxml spells namespaced ones ``{uri}local``)."""
    if not key.startswith("{"):
        return key
    qname = etree.QName(key)
    if qname.namespace == _XML_NS:
        return f"xml:{qname.localname}"
    for prefix, uri in (element.nsmap or {}).items():
        if uri == qname.namespace and prefix:
            return f"{prefix}:{qname.localname}"
    return qname.localname


def read_xml(data: bytes | str, *, max_depth: int = MAX_DEPTH) -> XMLDocument:
    """Parse scene text safely. Raises :class:`XMLReadError` (E101/E102/E104) if it cannot be read.

    The strict parse comes first; only if it fails are the tokenizer's repairs applied (and returned,
    for W105 warnings) and the repaired text parsed with the same hardened parser.
    """
    if isinstance(data, bytes):
        text, decode_problem = decode(data)
    else:
        text, decode_problem = data, None
    if text.startswith("\ufeff"):
        text = text[1:]
    if "\r" in text:
        # XML normalizes line ends before parsing anyway; doing it first keeps our line count
        # identical to libxml2's for old-Mac (CR-only) files.
        text = text.replace("\r\n", "\n").replace("\r", "\n")
    result = scan(text, max_depth)
    if result.forbidden is not None:
        line, keyword = result.forbidden
        raise XMLReadError(
            "E102",
            line,
            f"<!{keyword}> declarations are not allowed in scenes (no DTDs, no entities: "
            "they are how XML external-entity and entity-expansion attacks work)",
            "remove the declaration; SOFA scenes never need one",
        )
    if result.too_deep is not None:
        raise XMLReadError(
            "E104",
            result.too_deep,
            f"elements nested more than {max_depth} levels deep",
            "flatten the scene; real scenes are a few levels deep",
        )
    root = None
    failure: XMLReadError | None = None
    repairs: list[Repair] = []
    if decode_problem is None:
        try:
            root = _parse_bytes(_to_utf8(text))
        except (etree.XMLSyntaxError, etree.LxmlError, ValueError) as exc:
            failure = _syntax_error(exc, repaired=False, last_line=_last_line(text))
    if root is None:
        repairs = ([decode_problem] if decode_problem else []) + result.repairs
        if not repairs:
            assert failure is not None
            raise failure
        if failure is not None and failure.code != "E101":
            raise failure
        try:
            root = _parse_bytes(_to_utf8(result.apply(text)))
        except (etree.XMLSyntaxError, etree.LxmlError, ValueError) as exc:
            raise _syntax_error(exc, repaired=True, last_line=_last_line(text)) from None
    _check_tree(root)
    tags: dict[Any, StartTag] = {}
    elements = list(root.iter())
    if len(elements) == len(result.tags) and all(
        tag_name(el) == tag.name for el, tag in zip(elements, result.tags, strict=True)
    ):
        tags = dict(zip(elements, result.tags, strict=True))
    return XMLDocument(root, tags, sorted(repairs, key=lambda r: r.line))
