"""Work in a forked child beside the caller (tollcli.job.forked_work): its result or its error comes back, a child that
dies is an error and not a wait, and a caller that never reads the result leaves no child behind it."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from tollcli.errors import DataError
from tollcli.job.forked_work import ForkedWork

pytestmark = pytest.mark.skipif(not hasattr(os, "fork"), reason="no os.fork here")


def test_a_result_larger_than_a_pipe_comes_back_whole():
    big = np.arange(2_000_000, dtype=np.int64)  # 16 MB: the child writes far more than a pipe holds
    work = ForkedWork(lambda: (big * 3, os.getpid()))
    values, child = work.result()
    assert np.array_equal(values, big * 3) and child != os.getpid()
    assert work.result()[1] == child  # read once, kept


def test_the_childs_error_is_raised_here_as_it_was_raised_there():
    def fail():
        raise DataError("drive.ubx: line 3: not a u-blox frame")

    work = ForkedWork(fail)
    with pytest.raises(DataError, match="drive.ubx: line 3: not a u-blox frame"):
        work.result()


def test_an_error_that_cannot_be_pickled_comes_back_named():
    class Local(Exception):  # a class defined in a function: pickling it fails
        pass

    def fail():
        raise Local("what went wrong")

    with pytest.raises(RuntimeError, match="Local: what went wrong"):
        ForkedWork(fail).result()


def test_a_child_that_dies_is_an_error_not_a_wait():
    with pytest.raises(RuntimeError, match="ended without a result .exit status 3"):
        ForkedWork(lambda: os._exit(3)).result()


def test_a_caller_that_ends_without_reading_leaves_no_child_holding_its_output():
    """The caller exits while the child still works; the child's write then fails and it ends: whoever reads the caller's
    output (a shell pipe, a test's subprocess) sees its end at once, not when a lingering child lets go of it."""
    script = textwrap.dedent("""
        import time
        from tollcli.job.forked_work import ForkedWork
        work = ForkedWork(lambda: (time.sleep(1.0), b"x" * (1 << 20))[1])  # more than a pipe holds, after a while
        print("parent done", flush=True)
    """)  # fmt: skip
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, timeout=60)
    assert done.returncode == 0 and done.stdout == b"parent done\n"  # the child's end closed the output: no hang here
