"""SWA segmentation (public surface assembled once every module lands)."""
