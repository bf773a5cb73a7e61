"""``python -m voxgi_addon.files.gfg info FILE`` / ``python -m voxgi_addon.files.gfg verify FILE``."""
import sys

from .cli import main

sys.exit(main())
