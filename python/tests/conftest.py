"""The module under test: <build>/python (DENSEMAP_PYTHON_DIR, set by CTest), else the
installed one. The data and programs the tests need come from the environment CTest sets."""

import os
import sys

_built = os.environ.get("DENSEMAP_PYTHON_DIR")
if _built:
    sys.path.insert(0, _built)
