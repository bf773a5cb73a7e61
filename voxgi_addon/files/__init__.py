"""Files: multilayer OpenEXR, PNG strips and GFG-like asset files (docs/gfg.md)."""
