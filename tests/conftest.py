"""Scripts the tests run in a subprocess (``python script.py`` puts the script's folder first on
``sys.path``) import this checkout's packages, not whichever checkout the environment installed:
a copy of the repository tested with a shared virtual environment tests itself."""

import os
from pathlib import Path

ROOT = str(Path(__file__).resolve().parents[1])
os.environ["PYTHONPATH"] = os.pathsep.join(
    [ROOT] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p and p != ROOT])
