"""Figures are records, not prose: no measured-looking figure in a source comment or docstring.

A timing, a rate, a speed-up or a memory size measured on one box goes stale the day the code or
the box changes, and a comment cannot say when or how it was taken. Such figures live in the
records (experiments/records, dsfec_jax/profile/records) and the docs pages that hold each part's
measurement history; the code keeps one line of why and the command that re-measures.
"""

import ast
import io
import re
import tokenize
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
ROOTS = ("dsfec_jax", "search", "experiments")

# Conservative: only forms that are (almost) always a measurement. Durations in plain seconds
# ("a 1 s velocity arrow"), sizes in MB (the papers' model sizes) and commit hashes (the sources
# of ported code) are too often facts to flag.
FIGURE = re.compile(
    r"\d(?:[\d,.]*\d)?\s?(?:ms|µs|MiB|GiB)\b"                                      # a time or a memory size
    r"|\d(?:[\d,.]*\d)?\s?(?:fps|FPS|req/s|(?:frames|maps|batches|steps|samples|images)/s)\b"  # a rate
    r"|\d(?:[\d.]*\d)?\s?x (?:faster|slower)\b"                                    # a speed-up
    r"|\d(?:[\d.]*\d)?\s?(?:s|seconds?|minutes?) (?:a|per) (?:frame|step|image|map|call|batch)\b")

# (file, the figure as the finder reports it) -> why it is a fact, not a measurement
FACTS = {
    ("dsfec_jax/core/host_memory.py", "2 MiB"): "the x86-64 huge-page size",
    ("dsfec_jax/data/rd/synthetic/spectra.py", "4.6 ms"): "a chirp frame's duration, 64 x 2 x 36 us",
    ("dsfec_jax/edge/loadtest.py", "10 fps"): "what `--rate 10` means",
    ("dsfec_jax/edge/uplink.py", "10 frames/s"): "a device's frame rate, the case the kept-alive connection serves",
    ("experiments/edge_uplink.py", "100 ms"): "the threshold the outage measurement counts frames over",
}


def prose(source: str) -> list[tuple[int, str]]:
    """(line, text) of every comment and docstring (any string that stands alone as a statement)."""
    found = [(tok.start[0], tok.string) for tok in tokenize.generate_tokens(io.StringIO(source).readline)
             if tok.type == tokenize.COMMENT]
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant) and isinstance(node.value.value, str):
            found.append((node.lineno, node.value.value))
    return sorted(found)


def measured_figures(source: str) -> list[tuple[int, str]]:
    """(line, figure) of each measured-looking figure in the comments and docstrings of `source`."""
    if not FIGURE.search(source):  # most files: no figure anywhere, nothing to parse
        return []
    return [(line + text[:m.start()].count("\n"), m.group()) for line, text in prose(source)
            for m in FIGURE.finditer(text)]


def sources() -> list[str]:
    return sorted(str(p.relative_to(ROOT)) for root in ROOTS for p in (ROOT / root).rglob("*.py"))


def test_no_measured_figures_in_source_comments():
    bad = {}
    for name in sources():
        hits = [f"line {line}: {fig}" for line, fig in measured_figures((ROOT / name).read_text())
                if (name, fig) not in FACTS]
        if hits:
            bad[name] = hits
    assert not bad, ("measured figures belong in a record or a docs/ page, with the command that "
                     f"re-measures them; the comment keeps the why: {bad}")


def test_every_fact_exemption_is_still_needed():
    """An exemption whose figure went away would silently allow the next one."""
    stale = [key for key in FACTS if key[1] not in [f for _, f in measured_figures((ROOT / key[0]).read_text())]]
    assert not stale


@pytest.mark.parametrize("text, expected", [
    ('"""Why: the loop is faster: 6.5 ms against 40.8 ms for XLA\'s form."""\n', ["6.5 ms", "40.8 ms"]),
    ("x = 1  # XLA on CPU runs this ~7x faster than a grouped conv\n", ["7x faster"]),
    ("def f():\n    \"\"\"Doc.\n\n    15 maps/s with the default pool, 17.7 frames/s at 1 thread.\"\"\"\n",
     ["15 maps/s", "17.7 frames/s"]),
    ("# listing 50k names on every frame cost 2.3 s a frame\n", ["2.3 s a frame"]),
    ("# peak 1,634 MiB\n", ["1,634 MiB"]),
])
def test_the_finder_can_fail(text, expected):
    assert [fig for _, fig in measured_figures(text)] == expected


def test_the_finder_leaves_code_and_facts_alone():
    """Strings that are values (format strings, help texts built from data) are not prose, and a
    size in seconds or a 1x1 conv is no measurement."""
    text = ('x = f"{ms:.1f} ms"  # a 1 s velocity arrow, 3x3 convs, 2x the batch\n'
            'label = "latency (ms, batch 1)"\n')
    assert measured_figures(text) == []
