"""lburst: learned features from low-light robotic bursts, and 3D reconstruction from them."""

from lburst.extract import LBurst, MultiScaleConfig
from lburst.features import Features
from lburst.model import LBurstNet, NetConfig, load_checkpoint, save_checkpoint

__version__ = "0.1.0"

__all__ = ["LBurst", "MultiScaleConfig", "Features", "LBurstNet", "NetConfig", "load_checkpoint", "save_checkpoint"]
