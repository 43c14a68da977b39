"""Entry points for tools and users: a config's model with checked trained
weights (:func:`init_model`), the samples of a split through a config's
test pipeline, and its test set under a sensor corruption."""
from .corrupted_dataset import (build_corrupted_dataset, corrupted_dataset_cfg,
                                loaded_inputs)
from .inference import init_model
from .split_dataset import add_split_arguments, build_split_dataset

__all__ = [
    'add_split_arguments', 'build_corrupted_dataset', 'build_split_dataset',
    'corrupted_dataset_cfg', 'init_model', 'loaded_inputs'
]
