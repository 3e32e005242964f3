"""Marks shared by the test files."""

import pytest


def slow(*values):
    """A parametrization for CI's slow step (``-m slow``): where a comparison runs over several
    strain models or frames, the default step keeps one of them (each compiles programs of its
    own, tens of seconds) and the slow step checks the rest."""
    return pytest.param(*values, marks=pytest.mark.slow)
