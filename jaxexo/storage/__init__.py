"""Storage layer: the files a run writes and a device reads (the NumPy-only policy file format)."""
