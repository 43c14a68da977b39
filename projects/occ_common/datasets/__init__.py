"""Datasets of the occupancy plugins (registered in DATASETS).

``converters`` (needs nuscenes-devkit) and ``synthetic`` (the world
generator) are imported on demand by the tools, not here.
"""
from .nuscenes_occ_dataset import NuScenesOccDataset

__all__ = ['NuScenesOccDataset']
