"""lerobot-ocr: Object-Centric Recovery for LeRobot policies."""

__version__ = "0.1.0"
