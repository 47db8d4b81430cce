"""Ctrl-C held back while a file is written (the result's netCDF, a run's checkpoint)."""

import signal
import threading
from contextlib import contextmanager


@contextmanager
def interrupts_held():
    """Hold Ctrl-C (SIGINT) back until the block ends, then raise KeyboardInterrupt.

    A KeyboardInterrupt raised inside a writer can leave a file half-written and its library
    in a bad state:

    * inside the netCDF/HDF5 library it left xarray's HDF5 lock held and a file half-open;
      the next write (a sweep's next part, say) then waited on that lock for ever;
    * inside ``np.savez`` (a checkpoint, a zip) zipfile's clean-up raised "Can't close the
      ZIP file while there is an open writing handle", which replaced the interrupt: the run
      ended with an error (exit 2) and a traceback from ``ZipFile.__del__`` instead of
      stopping (exit 130).

    A write takes about a second at most, so the interrupt is taken after it. Only in the
    main thread (where Python delivers signals), else a no-op.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    received = []
    previous = signal.signal(signal.SIGINT, lambda signum, frame: received.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
    if received:
        raise KeyboardInterrupt
