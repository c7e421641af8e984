"""Print the "Corpus status" section of docs/components.md: how the SOFA corpus fares under ``sofac check``.

    python scripts/corpus_status.py                  # print the section (Markdown)
    python scripts/corpus_status.py --update-readme  # rewrite it in docs/components.md, between the markers
    python scripts/corpus_status.py --all [--run N [--seconds S]] [--tree DIR]
        # every scene of the corpus (or of DIR, e.g. SOFA's whole examples/ tree): how many check
        # clean, fail only on unsupported components (which, by frequency) or with other errors;
        # with --run, the clean ones are also compiled and run N steps, or as many as S seconds
        # of stepping allow (compiled and finite, refused at compile time, diverged, internal error)

Reads ``shared/corpus/sofa`` (``../shared`` beside the checkout, else ``$SOFAC_SHARED``): the 126
scenes of its ``manifest.json`` are classified as clean (no errors), failing only with unsupported
components (E222), or failing with other errors (listed, with the reason); then the components the
registry marks unsupported, and how many of SOFA's 87 regression scenes use supported ones only.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import sys
import time
from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import sofac
from sofac import registry
from sofac.check.checker import check_file
from sofac.cli.main import find_scenes
from sofac.diagnostics import Diagnostic, Diagnostics, SceneError
from sofac.front.parse import parse_scene
from sofac.pipeline import add_compile_refusals, compile_scene
from sofac.simulation.loader import ContactNotCompiled, SimulationDiverged

REPO = Path(__file__).resolve().parents[1]
README = REPO / "docs" / "components.md"  # the page that holds the section
BEGIN, END = "<!-- corpus-status -->", "<!-- /corpus-status -->"
_FILE_IN_MESSAGE = re.compile(r"file '([^']*)' not found")
# What the diagnostics alone do not say about some scenes (printed only while they still fail).
NOTES = {
    "Demos/collisionMultiple.scn": "The frog meshes are in SOFA's share/mesh but were not copied into it.",
    "Demos/collisionMultipleMask.scn": "The same frog meshes as collisionMultiple.scn.",
}


def find_shared() -> Path | None:
    candidates = [REPO.parent / "shared"]
    if os.environ.get("SOFAC_SHARED"):
        candidates.append(Path(os.environ["SOFAC_SHARED"]))
    return next((c for c in candidates if (c / "corpus" / "sofa").is_dir()), None)


@dataclass
class SceneResult:
    name: str
    expected: str
    errors: list[Diagnostic]
    omitted: dict[str, str]  # files the manifest says are not shipped: name -> why

    @property
    def codes(self) -> set[str]:
        return {d.code for d in self.errors}

    @property
    def kind(self) -> str:
        if not self.errors:
            return "clean"
        return "unsupported" if self.codes == {"E222"} else "other"

    def why(self) -> str:
        """The errors other than E222, briefly: each code with what it is about."""
        parts: list[str] = []
        by_code: dict[str, list[Diagnostic]] = {}
        for diag in self.errors:
            by_code.setdefault(diag.code, []).append(diag)
        for code, diags in sorted(by_code.items()):
            if code == "E222":
                continue
            if code == "E219":
                files = sorted({m.group(1) for d in diags if (m := _FILE_IN_MESSAGE.search(d.message))})
                by_reason: dict[str, list[str]] = {}
                for name in files:
                    by_reason.setdefault(self.omitted.get(name, "not in the corpus"), []).append(f"`{name}`")
                notes = [f"{', '.join(names)} ({reason})" for reason, names in by_reason.items()]
                parts.append(f"E219 missing file{'s' if len(files) > 1 else ''} {'; '.join(notes)}")
            else:
                first = diags[0]
                more = f" (+{len(diags) - 1} more)" if len(diags) > 1 else ""
                parts.append(f"{code} line {first.loc.line}: {first.message}{more}")
        if "E222" in self.codes:
            parts.append("and unsupported components (E222)")
        text = "; ".join(parts)
        return f"{text}. {NOTES[self.name]}" if self.name in NOTES else text


def check_manifest(corpus: Path) -> tuple[dict[str, object], list[SceneResult]]:
    manifest = json.loads((corpus / "manifest.json").read_text(encoding="utf-8"))
    results = []
    for entry in manifest["scenes"]:
        checked, diags = check_file(corpus / entry["scene"])
        add_compile_refusals(checked, diags)  # as `sofac check`: what the compile would refuse too
        omitted = {str(o["ref"]): str(o["why"]) for o in entry.get("omitted", ())}
        results.append(SceneResult(entry["scene"], entry["expected"], diags.errors, omitted))
    return manifest, results


def regression_scenes(shared: Path) -> list[str]:
    listing = shared / "reference" / "sofa-regression" / "scenes.regression-tests"
    names = []
    for line in listing.read_text(encoding="utf-8").splitlines():
        fields = line.split()
        if fields and not line.startswith("#") and fields[0].endswith((".scn", ".xml")):
            names.append(fields[0])
    return names


def components_of(path: Path) -> set[str]:
    """Canonical names of the components of a scene, includes and macros expanded."""
    scene = parse_scene(path, Diagnostics())
    names = set()
    for component in scene.root.components():
        resolution = registry.lookup(component.type_name)
        names.add(resolution.spec.name if resolution else component.type_name)
    return names


def _names(items: Iterable[str]) -> str:
    return ", ".join(f"`{n}`" for n in sorted(items)) or "none"


def render(shared: Path) -> str:
    corpus = shared / "corpus" / "sofa"
    manifest, results = check_manifest(corpus)
    source = manifest.get("source", {})
    commit = str(source.get("commit", "?"))[:10] if isinstance(source, dict) else "?"
    kinds = Counter(r.kind for r in results)
    negative = [r for r in results if r.expected.startswith("reject")]
    rejected = [r for r in negative if r.errors]
    accepted = [r for r in results if not r.expected.startswith("reject")]
    other = [r for r in results if r.kind == "other"]

    specs = {name: spec for name, spec in registry.all_components().items() if name != "Node"}
    unsupported = {name for name, spec in specs.items() if not spec.supported}
    regression = regression_scenes(shared)
    blockers: Counter[str] = Counter()
    only_supported = 0
    for name in regression:
        missing = components_of(corpus / name) & unsupported
        only_supported += not missing
        blockers.update(missing)
    used_in_manifest: Counter[str] = Counter()
    for r in results:
        used_in_manifest.update(components_of(corpus / r.name) & unsupported)

    lines = [
        f"Measured by `python scripts/corpus_status.py` (`--update-readme` rewrites this section; "
        f"sofac {sofac.__version__}) on the "
        f"{len(results)} scenes of `shared/corpus/sofa/manifest.json` (SOFA commit `{commit}`), "
        "without `--allow-unsupported`:",
        "",
        "| `sofac check` result | scenes |",
        "| --- | ---: |",
        f"| clean: no errors (warnings allowed) | {kinds['clean']} |",
        f"| errors, all of them unsupported components (E222) | {kinds['unsupported']} |",
        f"| other errors | {kinds['other']} |",
        "",
        f"Of the {len(accepted)} scenes the manifest expects to be accepted, "
        f"{sum(r.kind == 'clean' for r in accepted)} check clean, "
        f"{sum(r.kind == 'unsupported' for r in accepted)} fail only on unsupported components and "
        f"{sum(r.kind == 'other' for r in accepted)} fail with other errors (below). "
        f"All {len(negative)} negative scenes are rejected"
        if len(rejected) == len(negative)
        else f"Only {len(rejected)} of the {len(negative)} negative scenes are rejected",
    ]
    lines[-1] += " (every one of them with E222)." if all("E222" in r.codes for r in negative) else "."
    if other:
        lines += ["", "Scenes with other errors:", ""]
        lines += [f"- `{r.name}`: {r.why()}" for r in other]
    lines += [
        "",
        "Every `.scn` file of the corpus and every `.xml` file rooted at `<Node>` goes through "
        "`sofac check` without an exception, each diagnostic on the right line (`tests/test_corpus.py`).",
        "",
        f"**Unsupported components.** The registry knows {len(specs)} components, every class SOFA's "
        f"factory registers ({sum(s.from_sofa_source for s in specs.values())} of them only from SOFA's "
        "source, `scripts/sofa_components.py`); "
        f"{len(specs) - len(unsupported)} are supported and {len(unsupported)} are validated only "
        "(E222 unless `--allow-unsupported`). Those described by hand:",
        "",
        _names({n for n in unsupported if not specs[n].from_sofa_source}) + ".",
        "",
        f"Of the unsupported ones, {len(used_in_manifest)} appear in the manifest's scenes (in how many): "
        + ", ".join(f"`{n}` ({c})" for n, c in sorted(used_in_manifest.items(), key=lambda x: (-x[1], x[0])))
        + ".",
        "",
        f"**Regression scenes.** {only_supported} of SOFA's {len(regression)} regression scenes "
        "(`shared/reference/sofa-regression/scenes.regression-tests`) use supported components only; "
        "every component of all of them is registered. The others need: "
        + ", ".join(f"`{n}` ({c})" for n, c in sorted(blockers.items(), key=lambda x: (-x[1], x[0])))
        + ".",
    ]
    return "\n".join(lines) + "\n"


def run_outcome(path: Path, steps: int, budget: float | None = None) -> tuple[str, int]:
    """Compile a scene that checks clean and run it: "runs" (finite after ``steps`` steps, or
    after as many as ``budget`` seconds of stepping allow), "refused EXXX" (the compile stopped
    with a diagnostic), "diverged", "stopped by the contact guard" (ContactNotCompiled, which
    check announces with W234) or "internal: ..."; and the number of steps run."""
    done = 0
    try:
        sim = compile_scene(path).instantiate()
        start = time.perf_counter()
        while done < steps and (budget is None or time.perf_counter() - start < budget):
            sim.step(1 if budget is not None else steps)
            done = sim.steps
    except SceneError as error:
        codes = sorted({d.code for d in error.diagnostics if d.severity.name == "ERROR"})
        return "refused " + ",".join(codes or ["?"]), done
    except SimulationDiverged:
        return "diverged", done
    except ContactNotCompiled:  # what check's W234 announces
        return "stopped by the contact guard", done
    except Exception as error:  # an internal error is what this report looks for
        return f"internal: {type(error).__name__}: {error}".splitlines()[0][:160], done
    return "runs", done


def render_tree(tree: Path, steps: int | None, budget: float | None = None) -> str:
    """The whole-tree report: every scene ``find_scenes`` finds under ``tree``."""
    scenes = sorted(find_scenes([str(tree)]))
    kinds: Counter[str] = Counter()
    blockers: Counter[str] = Counter()
    other: list[str] = []
    clean: list[Path] = []
    for path in scenes:
        name = path.relative_to(tree).as_posix()
        try:
            checked, diags = check_file(path)
            add_compile_refusals(checked, diags)
        except Exception as error:  # reported, not raised: the report goes on
            kinds["internal error in check"] += 1
            other.append(f"- `{name}`: internal error in check: {type(error).__name__}: {error}")
            continue
        errors = diags.errors
        if not errors:
            kinds["clean"] += 1
            clean.append(path)
            continue
        codes = {d.code for d in errors}
        blockers.update(
            {m.group(1) for d in errors if d.code == "E222" if (m := _UNSUPPORTED.search(d.message))}
        )
        if codes == {"E222"}:
            kinds["unsupported"] += 1
        else:
            kinds["other"] += 1
            first = next(d for d in errors if d.code != "E222")
            other.append(f"- `{name}`: {first.code} line {first.loc.line}: {first.message}")
    lines = [
        f"`python scripts/corpus_status.py --all{f' --run {steps}' if steps else ''}"
        f"{f' --seconds {budget:g}' if steps and budget is not None else ''}` on the "
        f"{len(scenes)} scenes of `{tree}` (sofac {sofac.__version__}):",
        "",
        "| `sofac check` result | scenes |",
        "| --- | ---: |",
        f"| clean: no errors (warnings allowed) | {kinds['clean']} |",
        f"| errors, all of them unsupported components (E222) | {kinds['unsupported']} |",
        f"| other errors | {kinds['other']} |",
    ]
    if kinds["internal error in check"]:
        lines.append(f"| internal error in check | {kinds['internal error in check']} |")
    if steps:
        outcomes: Counter[str] = Counter()
        not_running: list[str] = []
        cut_short: list[str] = []
        for path in clean:
            start = time.perf_counter()
            outcome, done = run_outcome(path, steps, budget)
            name = path.relative_to(tree).as_posix()
            seconds = time.perf_counter() - start
            print(
                f"{outcome}\t{done} steps\t{seconds:.0f} s\t{name}", file=sys.stderr, flush=True
            )  # progress
            outcomes[outcome.split(":")[0] if outcome.startswith("internal") else outcome] += 1
            if outcome != "runs":
                not_running.append(f"- `{name}`: {outcome}" + (f" (step {done + 1})" if done else ""))
            elif done < steps:
                cut_short.append(f"`{name}` ({done})")
        limit = f" (or as many as {budget:g} s of stepping allow)" if budget is not None else ""
        lines += ["", f"Of the {len(clean)} clean scenes, run {steps} steps each{limit}:", ""]
        lines += ["| outcome | scenes |", "| --- | ---: |"]
        lines += [f"| {outcome} | {count} |" for outcome, count in sorted(outcomes.items())]
        if not_running:
            lines += ["", "Clean scenes that do not run:", "", *not_running]
        if cut_short:
            lines += ["", f"Runs cut short by the time limit (steps run): {', '.join(cut_short)}."]
    lines += [
        "",
        "Unsupported components (E222), by the number of scenes they block: "
        + ", ".join(f"`{n}` ({c})" for n, c in sorted(blockers.items(), key=lambda x: (-x[1], x[0])))
        + ".",
    ]
    if other:
        lines += ["", "Scenes with other errors (the first one):", "", *other]
    return "\n".join(lines) + "\n"


# The component an E222 names: "unsupported component NAME at line N".
_UNSUPPORTED = re.compile(r"unsupported component (\S+) at line")


def update_readme(section: str, readme: Path = README) -> None:
    text = readme.read_text(encoding="utf-8")
    block = f"{BEGIN}\n{section}{END}\n\n"
    # From the start marker to the end marker, or (first run) to the next heading.
    pattern = re.compile(re.escape(BEGIN) + r".*?(?:" + re.escape(END) + r"|(?=\n## |\Z))\s*", re.DOTALL)
    if not pattern.search(text):
        raise SystemExit(f"corpus_status: no {BEGIN} marker in {readme}")
    text = pattern.sub(lambda _: block, text, count=1)
    readme.write_text(text.rstrip("\n") + "\n", encoding="utf-8")


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description="Print (or update) the corpus status section of docs/components.md."
    )
    parser.add_argument("--update-readme", action="store_true", help=f"rewrite the section in {README.name}")
    parser.add_argument("--all", action="store_true", help="report on every scene of the corpus (or --tree)")
    parser.add_argument("--tree", type=Path, help="with --all: the folder to search instead of the corpus")
    parser.add_argument(
        "--run", type=int, metavar="N", help="with --all: compile the clean scenes and run N steps"
    )
    parser.add_argument(
        "--seconds",
        type=float,
        metavar="S",
        help="with --run: stop a scene's run after S seconds of stepping",
    )
    args = parser.parse_args(argv)
    shared = find_shared()
    if args.all:
        tree = args.tree or (shared / "corpus" / "sofa" if shared else None)
        if tree is None or not tree.is_dir():
            print("corpus_status: no folder to report on (set SOFAC_SHARED or pass --tree)", file=sys.stderr)
            return 2
        sys.stdout.write(render_tree(tree, args.run, args.seconds))
        return 0
    if shared is None:
        print("corpus_status: shared/corpus/sofa not found (set SOFAC_SHARED)", file=sys.stderr)
        return 2
    section = render(shared)
    if args.update_readme:
        update_readme(section)
        print(f"updated {README}")
    else:
        sys.stdout.write(section)
    return 0


if __name__ == "__main__":
    sys.exit(main())
