"""The tables the docs show from a record are the record's: each figure a record's markdown
prints appears on the page that shows it (a re-run that moves a figure, or a page edited by hand,
fails here)."""

import json
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
RD_RECORDS = sorted((ROOT / "experiments" / "records" / "yolo_rd").glob("table*_quick.json"))
FIGURE = re.compile(r"-?\d+\.\d+ \(\d+\.\d+\)|[+-]\d+\.\d+ \[[+-]\d+\.\d+, [+-]\d+\.\d+\]")  # '7.9 (42.2)', '+0.4 [-2.2, +3.5]'


def figures(markdown: str) -> set[str]:
    return set(FIGURE.findall(markdown))


def test_there_are_records_to_check():
    assert len(RD_RECORDS) >= 3


@pytest.mark.parametrize("record", RD_RECORDS, ids=lambda p: p.stem)
def test_every_figure_of_an_rd_table_record_is_on_its_page(record):
    page = (ROOT / "docs" / "range-doppler.md").read_text()
    shown = figures(json.loads(record.read_text())["markdown"])
    assert shown and not shown - figures(page), sorted(shown - figures(page))


@pytest.mark.parametrize("space", ["dsfec", "yolov8n_adapter"])
def test_a_ranking_study_on_its_page_is_its_records(space):
    study = json.loads((ROOT / "search" / "nas" / "records" / f"ranking_{space}.json").read_text())["ranking"]
    page = (ROOT / "docs" / "search.md").read_text()
    for pair in study["pairs"]:
        row = rf"\| {pair['inherited']:.2f} \| (\*\*)?{pair['standalone']:.2f}(\*\*)? \|"
        assert re.search(rf"\| (\*\*)?{re.escape(pair['key'])}\b[^\n]*{row}", page), (pair["key"], row)
    assert f"**{study['tau']:+.2f} (exact one-sided p {study['p_value']:.2f})**" in page


def test_a_figure_missing_from_the_page_is_caught():
    assert figures("| 7.9 (42.2) | +0.4 [-2.2, +3.5] within noise |") - figures("| 7.9 (42.2) |") == {"+0.4 [-2.2, +3.5]"}
