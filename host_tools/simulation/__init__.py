"""The simulators: hdrg's own calibrated virtual gyroscope (sim and its parts), the foreign randomized-physics family, and the paper's experiments on them."""
