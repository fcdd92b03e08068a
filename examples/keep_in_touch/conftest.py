"""This project is not installed: make its package importable here and in the session's processes, which inherit the
environment. An installed project (``pip install -e .``) needs none of this."""

import os
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
os.environ["PYTHONPATH"] = os.pathsep.join([str(HERE), *filter(None, [os.environ.get("PYTHONPATH")])])
