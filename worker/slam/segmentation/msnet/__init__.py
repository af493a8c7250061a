"""MSNET, the paper's Vision-Transformer segmentation network (see DESIGN.md stage 1)."""
from worker.slam.segmentation.msnet.config import MsnetConfig
from worker.slam.segmentation.msnet.model import MSNet, MsnetOutput, build_msnet

__all__ = ["MSNet", "MsnetConfig", "MsnetOutput", "build_msnet"]
