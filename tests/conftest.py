"""Test-wide settings: Hypothesis runs the same examples on every run and machine.

``derandomize=True`` draws examples from a fixed seed (and skips the example
database), so a CI run is reproducible and a failure is reproduced by rerunning
the test; ``deadline=None`` because a loaded 2-core machine is no measure of
speed. ``HYPOTHESIS_PROFILE=explore`` turns the randomness back on to hunt for
new counterexamples locally.

Hypothesis also mixes literal constants of the loaded project modules into its
examples, so running a subset of the tests can draw other examples than the
full suite; each selection is still the same on every run.
"""

import os

from hypothesis import settings

settings.register_profile("ci", derandomize=True, deadline=None, database=None, print_blob=True)
settings.register_profile("explore", deadline=None)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))
