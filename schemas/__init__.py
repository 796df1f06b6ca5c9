"""Schemas: every table, source file, log stream and output declared once.

Also the base error class, units and enumerations. Imports nothing from the rest of the
suite; this package file imports nothing at all (every declaration by name:
:data:`schemas.catalog.ALL_SCHEMAS`).
"""
