"""MuJoCo dual-arm cell standing in for the Baxter and its wrist camera."""
