"""The bridge to the fixed point: model -> coefficient table (quantize), table files (export), run log -> input words -> the firmware reference -> compensated log (fixed_point)."""
