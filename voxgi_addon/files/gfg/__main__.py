"""``python -m voxgi_addon.gfg info FILE`` / ``python -m voxgi_addon.gfg verify FILE``."""
import sys

from .cli import main

sys.exit(main())
