"""Consistency rules of ``db validate``, one module per family; each is pure: frames in →
findings out. :mod:`dbtools.validate` runs them all."""
