"""Imported first by the fleet audit's fork server (``fieldlogs.audit.runner``), never elsewhere.

The fork server and the worker processes it forks then ignore SIGINT: Ctrl-C in a terminal
reaches the whole process group, and it is the coordinating process that handles it (drops
the queued runs, lets the running ones finish, keeps every finished run). Without this an
interrupt during the server's start-up prints an import traceback from the server.
"""

import signal

signal.signal(signal.SIGINT, signal.SIG_IGN)
