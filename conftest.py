"""Run the notebooks on short settings inside the test suite (they read FMSCAL_QUICK)."""

import os

os.environ.setdefault("FMSCAL_QUICK", "1")
