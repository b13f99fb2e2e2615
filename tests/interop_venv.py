"""Where the tests find the real ML-Agents 1.1.0 interop peer: ``.venv-interop`` beside the
checkout, or the folder named by INTEROP_VENV (relative to the checkout or absolute),
the same variable scripts/ensure_interop_venv.sh reads; .ci/run's second Python leg sets it."""
from __future__ import annotations

import os
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
INTEROP_VENV = REPO / os.environ.get("INTEROP_VENV", ".venv-interop")
INTEROP_PYTHON = INTEROP_VENV / "bin" / "python"
