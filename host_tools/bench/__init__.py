"""Measurement benchmarks (`hdrg bench accuracy|loop`) and target costs (`hdrg cost`)."""
