"""core.progress: a stage announces itself, beats while it runs, and says its time."""

import io
import re
import time

from dsfec_jax.core import progress


def test_a_stage_beats_while_it_runs_and_reports_its_time():
    out = io.StringIO()
    with progress.stage("compiling the test step", usual="a moment", heartbeat_s=0.05, stream=out):
        time.sleep(0.3)
    lines = out.getvalue().splitlines()
    assert lines[0] == "compiling the test step... (usually a moment)"
    beats = [line for line in lines if line.startswith("... still compiling the test step")]
    assert len(beats) >= 2, lines
    assert re.fullmatch(r"compiling the test step: done in 0\.\d s", lines[-1]), lines


def test_a_stage_says_its_time_even_when_its_body_fails():
    out = io.StringIO()
    try:
        with progress.stage("loading", stream=out):
            raise ValueError("broken file")
    except ValueError:
        pass
    assert out.getvalue().splitlines()[-1].startswith("loading: done in")


def test_quiet_silences_every_stage(monkeypatch):
    monkeypatch.setenv("DSFEC_QUIET", "1")
    out = io.StringIO()
    with progress.stage("compiling", heartbeat_s=0.01, stream=out):
        time.sleep(0.05)
    assert out.getvalue() == ""
