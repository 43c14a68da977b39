"""What ``tools/deployment/export_onnx.py`` needs to know of one graph."""
from typing import Callable, Dict, NamedTuple, Tuple

from torch import Tensor, nn


class GraphSpec(NamedTuple):
    """A model's exportable part and how to feed it.

    Attributes:
        module (nn.Module): The part, on plain tensors, in eval mode.
        input_names (tuple[str]): Its inputs, in call order.
        output_names (tuple[str]): Its outputs. For the prediction graph
            (``part`` '') the first is the occupancy logits (B,
            num_classes, X, Y, Z), checked against the model's own
            ``_forward``.
        dynamic_axes (dict): Input / output name -> axis -> symbolic name.
        feeds (Callable[[dict], dict[str, Tensor]]): A collated batch of
            one -> the inputs, by name (what runs outside the graph, such
            as a LiDAR encoder, runs here in PyTorch).
        outside (str): What runs outside the graph, in words ('' for
            nothing).
        part (str): '' for the graph that predicts the occupancy; a name
            for a further graph of the model (written as
            ``<out>.<part>.onnx``, checked output by output against
            ``module`` in PyTorch). Defaults to ''.
    """
    module: nn.Module
    input_names: Tuple[str, ...]
    output_names: Tuple[str, ...]
    dynamic_axes: Dict[str, Dict[int, str]]
    feeds: Callable[[dict], Dict[str, Tensor]]
    outside: str
    part: str = ''
