"""Every command in the README's set-up and quick starts parses as written: a renamed flag, a
dropped choice or a moved module fails here instead of in a new user's first hour. (Parsing
only: running them is minutes each; the tests of each command run them with tiny budgets.)"""

import importlib
import re
import shlex
from pathlib import Path

import pytest

from dsfec_jax import cli

README = Path(__file__).resolve().parents[1] / "README.md"
SECTIONS = ("## Set-up", "## Quick start")
# each `python -m MODULE` the README runs -> its function that parses argv without running anything
PARSERS = {"search.blocks": ("search.blocks", "arguments"), "search.nas": ("search.nas.__main__", "parse"),
           "dsfec_jax.profile": ("dsfec_jax.profile.__main__", "parse"),
           "dsfec_jax.data": ("dsfec_jax.data.__main__", "parse"),
           "dsfec_jax.profile.device_check": ("dsfec_jax.profile.device_check.__main__", "parse")}
NOT_OURS = {"venv", "pytest"}  # python -m venv / pytest: the standard library's and pytest's own


def readme_commands(text: str) -> list[str]:
    """The indented command lines of the README's set-up and quick-start sections, split at
    `&&`, without comments and shell redirections."""
    commands = []
    for section in re.split(r"(?m)^(?=## )", text):
        if not section.startswith(SECTIONS):
            continue
        for line in re.findall(r"(?m)^    (\S.*)$", section):
            for part in line.split("&&"):
                part = re.sub(r"\s+#.*$", "", part).strip()
                part = re.sub(r"\s*>\s*\S+$", "", part)
                commands.append(part)
    return commands


def parse_command(command: str) -> None:
    words = shlex.split(command)
    program = Path(words[0]).name
    if program == "dsfec":
        cli.parse(words[1:])
    elif program == "python" and words[1] == "-m":
        module = words[2]
        if module in NOT_OURS:
            return
        assert module in PARSERS, f"README runs `python -m {module}`: add its parser to PARSERS"
        where, function = PARSERS[module]
        getattr(importlib.import_module(where), function)(words[3:])
    elif program in ("pip", "chmod"):
        return
    else:
        raise AssertionError(f"README command {command!r}: unknown program {words[0]!r}")


COMMANDS = readme_commands(README.read_text())


def test_the_readme_has_commands_to_check():
    assert any(c.startswith("dsfec train") for c in COMMANDS) and any("search.blocks" in c for c in COMMANDS)


@pytest.mark.parametrize("command", COMMANDS)
def test_a_readme_command_parses_as_written(command):
    try:
        parse_command(command)
    except SystemExit as exit_:
        pytest.fail(f"README command {command!r} does not parse (exit {exit_.code})")


def test_a_wrong_flag_fails_the_check():
    with pytest.raises(SystemExit):
        parse_command("dsfec eval --model dsfec_s --nframes 200")
    with pytest.raises(SystemExit):
        parse_command("python -m search.blocks --stages 2")
