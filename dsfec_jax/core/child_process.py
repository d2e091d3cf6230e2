"""Run a child process whose stderr the user sees as it comes.

The bench workers (`dsfec bench`, `dsfec bench --train`) run in child processes pinned to their
thread counts. Their progress (exporting, compiling, a bar over the repeats) is on their stderr;
captured until the child ended, a command sat silent for minutes (issue 51). Here the stderr is
passed on chunk by chunk, raw, so tqdm's carriage-return redraws survive, and its tail is kept
for the error message when the child fails.
"""

from __future__ import annotations

import codecs
import subprocess
import sys


def run_passing_stderr(cmd: list[str], env: dict, keep: int = 3000) -> tuple[int, str]:
    """Run `cmd` (stdout discarded: the workers write their records to a file) with its stderr passed
    on to ours as it comes -> (exit code, the last `keep` characters of that stderr)."""
    decoder, tail = codecs.getincrementaldecoder("utf-8")(errors="replace"), ""
    with subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE) as proc:
        while chunk := proc.stderr.read1(4096):
            text = decoder.decode(chunk)
            sys.stderr.write(text)
            sys.stderr.flush()
            tail = (tail + text)[-keep:]
    return proc.returncode, tail
