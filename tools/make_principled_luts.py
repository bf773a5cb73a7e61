"""Write ``voxgi_addon/gi/principled_luts.npz``: the GGX tables of the Principled BSDF model
(``voxgi_addon/gi/principled.py``; docs/gi_pipeline.md "Principled materials").

Deterministic quadrature, a few minutes of numpy: ``python tools/make_principled_luts.py``.
"""
from __future__ import annotations

import pathlib
import sys
import time

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))

from voxgi_addon.gi.principled import LUT_PATH, compute_luts  # noqa: E402


def main() -> None:
    start = time.perf_counter()
    luts = compute_luts()
    np.savez_compressed(LUT_PATH, **{name: table.astype(np.float32) for name, table in luts.items()})
    print(f"wrote {LUT_PATH} ({LUT_PATH.stat().st_size} bytes) in {time.perf_counter() - start:.0f} s")


if __name__ == "__main__":
    main()
