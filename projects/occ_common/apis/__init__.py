"""Entry points for tools and users: a config's model with checked trained
weights (:func:`init_model`) and the samples of a split through a config's
test pipeline."""
from .inference import init_model
from .split_dataset import add_split_arguments, build_split_dataset

__all__ = ['add_split_arguments', 'build_split_dataset', 'init_model']
