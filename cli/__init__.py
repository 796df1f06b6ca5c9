"""The ``trainpos`` command line: thin Typer commands over dbtools and fieldlogs."""
