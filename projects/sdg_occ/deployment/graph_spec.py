"""The exportable part of an ``SDGOcc`` and how to feed it."""
import copy
from typing import Dict, Optional

import torch
from torch import Tensor, nn

from projects.occ_common.deployment.graph_spec import GraphSpec
from projects.occ_common.deployment.samples import camera_feeds
from .camera_graph import INPUT_NAMES as CAMERA_INPUT_NAMES
from .camera_graph import OUTPUT_NAMES, SDGCameraGraph
from .fusion_graph import INPUT_NAMES as FUSION_INPUT_NAMES
from .fusion_graph import SDGFusionDenseGraph

#: What SDG-Fusion runs outside its graph.
FUSION_OUTSIDE = ('the SPVCNN LiDAR encoder (sparse convolutions): '
                  "lidar_bev = model.lidar_encoder([points])['bev'], by "
                  'PyTorch (or spconv) beside the runtime')


def sdg_graph_spec(model: nn.Module,
                   time_dim: Optional[int] = None,
                   with_bev: bool = False) -> GraphSpec:
    """:class:`GraphSpec` of an ``SDGOcc``.

    SDG-KL and the camera rows: the whole prediction path
    (:class:`SDGCameraGraph`). SDG-Fusion: everything but the LiDAR
    encoder, whose BEV is an input (:class:`SDGFusionDenseGraph`).

    Args:
        model (SDGOcc): In eval mode.
        time_dim (int, optional): Column of the points' time lag.
            Defaults to None.
        with_bev (bool): Also output the camera BEV. Defaults to False.

    Returns:
        GraphSpec: The graph; the point count is its one dynamic axis.
    """
    outputs = OUTPUT_NAMES if with_bev else OUTPUT_NAMES[:2]
    fusion = model.variant == 'fusion'
    graph = (SDGFusionDenseGraph if fusion else SDGCameraGraph)(
        model, time_dim, with_bev).eval()
    names = FUSION_INPUT_NAMES if fusion else CAMERA_INPUT_NAMES

    def feeds(batch: dict) -> Dict[str, Tensor]:
        out = camera_feeds(batch)
        if fusion:
            with torch.no_grad():
                data = model.data_preprocessor(copy.copy(batch), False)
                out['lidar_bev'] = model.extract_lidar_bev(
                    data['inputs'])['bev']
        if not model.view_transform.use_sdg:
            del out['points']
        return out

    if not model.view_transform.use_sdg:
        # The plain LSS lift (Table 3's baselines) reads no points.
        return GraphSpec(
            _WithoutPoints(graph).eval(),
            tuple(n for n in names if n != 'points'),
            outputs, {}, feeds, FUSION_OUTSIDE if fusion else '')
    return GraphSpec(graph, names, outputs, {'points': {0: 'num_points'}},
                     feeds, FUSION_OUTSIDE if fusion else '')


class _WithoutPoints(nn.Module):
    """A graph of a model whose lift reads no points: its inputs without
    ``points``."""

    def __init__(self, graph: nn.Module) -> None:
        super().__init__()
        self.graph = graph
        self.time_dim = graph.time_dim

    def forward(self, imgs: Tensor, *rest: Tensor):
        """``graph(imgs, None, *rest)``."""
        return self.graph(imgs, None, *rest)
