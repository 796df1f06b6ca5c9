"""Imported first by the replay's fork server (:mod:`fieldlogs.replay.pool`), never elsewhere.

The fork server and every worker it forks then

* ignore SIGINT: Ctrl-C in a terminal reaches the whole process group, and it is the
  coordinating process that handles it (it stops the workers itself); without this an
  interrupt during the server's start-up prints an import traceback from the server;
* die with their parent (Linux ``PR_SET_PDEATHSIG``): the server with the coordinating
  process, each worker with the server (:func:`fieldlogs.replay.pool.worker_init`). A
  coordinator killed with SIGKILL so leaves no server and no worker behind, and the
  resource tracker exits by itself once no process holds its pipe any more.
"""

import ctypes
import os
import signal
import sys

#: The fork server's pid, inherited by the workers it forks.
SERVER_PID = os.getpid()
PR_SET_PDEATHSIG = 1  # linux/prctl.h


def die_with_parent() -> bool:
    """Ask the kernel to SIGKILL this process when its parent exits (Linux only)."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        return bool(libc.prctl(PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0) == 0)
    except (OSError, AttributeError):
        return False


signal.signal(signal.SIGINT, signal.SIG_IGN)
die_with_parent()
