"""Burst scenes for reconstruction: the synthetic night flight with exact ground truth
(:mod:`lburst.scenes.night_flight`) and the scene folder's reference cameras
(:mod:`lburst.scenes.reference`)."""
