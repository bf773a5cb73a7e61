"""Engine lane: plain numpy, no Blender. The engine is imported as top-level ``voxgi_addon``."""
import pathlib
import sys

REPO_ROOT = pathlib.Path(__file__).resolve().parents[2]
if str(REPO_ROOT) not in sys.path:
    sys.path.insert(0, str(REPO_ROOT))
