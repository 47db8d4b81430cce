"""Loading a kernel from Numba's disk cache is booked with compilation, not as model time
(tolsim._jit.compile_seconds, issue 26 item 8).

Numba sends ``numba:compile`` only while it compiles; a kernel loaded from its cache (about
1 s for a study's kernels in a fresh process) sent nothing, and that time was counted as
"re-solved with the full model" and in the balls/s. Checked in fresh processes on a kernel
module of its own (a cold cache, then a warm one), and for the process clock with two
threads whose spans overlap.
"""

import os
import subprocess
import sys
import textwrap
import threading
import time

from numba.core import event as numba_event

import tolsim._jit as jit_defaults

KERNEL = textwrap.dedent("""\
    import numpy as np
    from tolsim._jit import jit


    @jit
    def total(x):
        s = 0.0
        for i in range(x.size):
            s += np.sin(x[i]) * np.cos(x[i])
        return s
    """)
RUN = textwrap.dedent("""\
    import sys
    import numpy as np
    from numba.core import event
    from tolsim import _jit


    class Count(event.Listener):
        n = 0

        def on_start(self, e):
            Count.n += 1

        def on_end(self, e):
            pass


    event.register("numba:compile", Count())
    sys.path.insert(0, sys.argv[1])
    from kmod import total
    before = _jit.compile_seconds()
    total(np.ones(3))
    print(Count.n, _jit.compile_seconds() - before)
    """)


def run(root, cache):
    out = subprocess.run([sys.executable, "-c", RUN, str(root)], check=True,
                         capture_output=True, text=True,
                         env=dict(os.environ, NUMBA_CACHE_DIR=str(cache)))
    compiles, seconds = out.stdout.split()
    return int(compiles), float(seconds)


def test_loading_from_the_cache_is_booked(tmp_path):
    (tmp_path / "kmod.py").write_text(KERNEL)
    compiles, compiled = run(tmp_path, tmp_path / "cache")
    assert compiles >= 1 and compiled > 0  # a cold cache compiles
    compiles, loaded = run(tmp_path, tmp_path / "cache")
    assert compiles == 0  # warm: nothing compiles, Numba sends no numba:compile ...
    assert loaded > 0  # ... and the load is booked all the same (was 0.0 before issue 26)


def span(name, entered, leave):
    numba_event.start_event(name)
    entered.set()
    leave.wait(5)
    numba_event.end_event(name)


def test_the_process_clock_counts_overlapping_spans_once():
    """Two threads in the compiler at once (one compiling, one waiting for the lock) are
    one span of wall time: the process clock is the union of the threads' spans, so that
    subtracting it from a wall time never gives less than the model time."""
    clock = jit_defaults._CompileClock()
    numba_event.register("numba:compiler_lock", clock)
    try:
        a_in, b_in, a_out, b_out = (threading.Event() for _ in range(4))
        t0 = time.perf_counter()
        a = threading.Thread(target=span, args=("numba:compiler_lock", a_in, a_out))
        a.start()
        a_in.wait(5)
        b = threading.Thread(target=span, args=("numba:compiler_lock", b_in, b_out))
        b.start()
        b_in.wait(5)
        time.sleep(0.05)
        a_out.set()
        a.join()
        time.sleep(0.05)
        b_out.set()
        b.join()
        t1 = time.perf_counter()
    finally:
        numba_event.unregister("numba:compiler_lock", clock)
    union = clock.seconds(thread=False)
    # inside the bracket [first start, last end] (the sum of the two spans would exceed it
    # by A's span, >= 0.05 s)
    assert 0.1 <= union <= t1 - t0
