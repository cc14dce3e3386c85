"""lburst: learned features from low-light robotic bursts, and 3D reconstruction from them."""

from lburst import methods, noise, simulate
from lburst.extract import LBurst, MultiScaleConfig
from lburst.features import Features
from lburst.io import BurstError, load_burst, save_burst
from lburst.model import CheckpointError, LBurstNet, NetConfig, load_checkpoint, save_checkpoint
from lburst.simulate import simulate_burst

__version__ = "0.1.0"

__all__ = [
    "LBurst", "MultiScaleConfig", "Features", "LBurstNet", "NetConfig", "load_checkpoint", "save_checkpoint",
    "CheckpointError", "BurstError", "load_burst", "save_burst", "simulate_burst", "methods", "noise", "simulate",
]
