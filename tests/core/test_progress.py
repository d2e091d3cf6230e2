"""core.progress: a stage announces itself, beats while it runs, and says its time."""

import io
import re
import sys
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


def test_a_bar_runs_its_first_item_inside_a_stage_and_draws_on_stderr(capsys):
    seen = []
    for item in progress.bar(range(3), "detecting", first="compiling the predictor", unit="batch"):
        seen.append(item)
        if item == 0:
            time.sleep(0.05)  # the first item's work happens while the stage is open
    err = capsys.readouterr().err
    assert seen == [0, 1, 2] and "detecting" in err and "3/3" in err
    assert err.count("compiling the predictor...") == 1
    assert re.search(r"compiling the predictor: done in 0\.\d s", err)
    assert capsys.readouterr().out == ""


def test_a_stage_line_lifts_a_running_bar_onto_a_line_of_its_own(capsys):
    from tqdm import tqdm

    with tqdm(total=2, desc="training") as bar:
        bar.update(1)
        with progress.stage("compiling"):
            pass
    lines = capsys.readouterr().err.replace("\r", "\n").splitlines()
    assert "compiling..." in lines  # not glued to the end of the bar's line


def test_a_generation_bar_shows_only_once_the_generation_is_slow(capsys, monkeypatch):
    monkeypatch.setattr(progress, "GENERATION_DELAY_S", 0.05)  # the 2 s of a real generation, scaled down
    assert list(progress.generating(range(2), "generating quick maps")) == [0, 1]  # done before the delay
    assert "generating quick maps" not in capsys.readouterr().err
    for _ in progress.generating(range(4), "generating slow maps"):
        time.sleep(0.04)
    assert "generating slow maps" in capsys.readouterr().err


def test_the_watchdog_names_the_innermost_phase_when_stderr_is_quiet(capsys):
    with progress.watched("dsfec test", heartbeat_s=0.2, poll_s=0.02):
        time.sleep(0.35)  # no phase yet: the start
        with progress.doing("loading the model"):
            time.sleep(0.35)
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.startswith("... dsfec test: still")]
    assert any("starting" in line for line in lines), err
    assert any("still loading the model" in line for line in lines), err


def test_the_watchdog_keeps_quiet_while_the_command_speaks_and_gives_stderr_back(capsys):
    stream = sys.stderr
    with progress.watched("dsfec test", heartbeat_s=0.3, poll_s=0.02):
        for _ in range(12):
            print("working", file=sys.stderr)
            time.sleep(0.05)
    assert "still" not in capsys.readouterr().err
    assert sys.stderr is stream


def test_a_bar_is_a_phase_and_a_bar_left_early_gives_its_phase_back(capsys):
    with progress.watched("dsfec test", heartbeat_s=0.2, poll_s=0.02):
        for _ in progress.bar(range(3), "detecting in 3 frames"):
            time.sleep(0.3)
            break
        with progress.doing("writing the outputs"):
            time.sleep(0.3)
    lines = [line for line in capsys.readouterr().err.splitlines() if "still" in line]
    assert any("still detecting in 3 frames" in line for line in lines), lines
    assert "still writing the outputs" in lines[-1], lines
    assert progress._PHASES == []
