"""Test set-up shared by all of python/tests.

The package is normally installed (``make setup``); when it is not, tests
import it from the source tree so that they run on a bare checkout.
"""

import importlib.util
import sys
from pathlib import Path

if importlib.util.find_spec("scattertrack") is None:
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
