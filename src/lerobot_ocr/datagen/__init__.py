"""Demonstration dataset generators (scripted experts -> LeRobotDataset v3)."""
