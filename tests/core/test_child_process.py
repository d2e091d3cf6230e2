"""core.child_process: a child's stderr reaches ours as it comes, and its tail names a failure."""

import sys

from dsfec_jax.core.child_process import run_passing_stderr


def test_the_childs_stderr_passes_through_and_its_tail_is_kept(capsys):
    code = ("import sys; sys.stdout.write('records go to a file'); sys.stderr.write('compiling...\\r50%\\r100%\\n'); "
            "sys.stderr.write('x' * 50); sys.exit(3)")
    rc, tail = run_passing_stderr([sys.executable, "-c", code], env={}, keep=20)
    err = capsys.readouterr()
    assert rc == 3 and err.err == "compiling...\r50%\r100%\n" + "x" * 50  # raw: tqdm's redraws survive
    assert err.out == "" and tail == "x" * 20
