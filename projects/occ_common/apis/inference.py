"""A config's model with checked trained weights: the one way every tool
and the demo load a trained model."""
import os.path as osp
from typing import Optional, Union

import torch
from mmengine.config import Config
from torch import nn


def init_model(config: Union[str, Config],
               checkpoint: Optional[str] = None,
               device: str = 'cpu',
               cfg_options: Optional[dict] = None,
               cfg_options_raw: Optional[dict] = None,
               allow_key_mismatch: bool = False) -> nn.Module:
    """Build ``config``'s model and load ``checkpoint`` into it, checked.

    mmdet3d's ``init_model`` with ``tools/test.py``'s checks: the config's
    ``custom_imports`` register the plugins; the weights come through the
    restricted loader (every mmengine scheme: local files, ``https://``,
    ``torchvision://`` ...; nothing in the file can run code) and are
    refused if they are not finite or, unless allowed, not this model's
    (:func:`~projects.occ_common.engine.checkpoint_check.load_checked_weights`).
    Before, a checkpoint of another model was loaded silently and the tools
    drew, measured or exported a randomly initialised model.

    Args:
        config (str | Config): Config file or a loaded config.
        checkpoint (str, optional): Weights (a Runner checkpoint or a state
            dict). None keeps the random initialisation (for timing and
            export checks). Defaults to None.
        device (str): Where the model goes. Defaults to 'cpu'.
        cfg_options (dict, optional): Overrides merged into the config, as
            ``--cfg-options`` gives them, checked by
            :func:`~projects.occ_common.engine.config_checks.merge_cfg_options`.
            Defaults to None.
        cfg_options_raw (dict, optional): The typed text of each override
            (:class:`~projects.occ_common.engine.config_checks.CfgOptionsAction`).
            Defaults to None.
        allow_key_mismatch (bool): Accept missing, unexpected and reshaped
            keys (they keep their initialisation); non-finite weights are
            refused anyway. Defaults to False.

    Returns:
        nn.Module: The model in eval mode on ``device``, with the merged
        config as ``model.cfg`` (as mmdet3d's ``init_model``).

    Raises:
        FileNotFoundError: If the checkpoint does not exist.
        ValueError: If CUDA is asked for and absent, or the checkpoint holds
            no state dict, non-finite weights or, unless allowed, keys or
            shapes other than the model's (naming the file and the first
            mismatched keys).
        RefusedGlobalError: If the file pickles code (nothing of it ran).
    """
    from mmengine.registry import MODELS, init_default_scope
    from mmengine.runner.checkpoint import _load_checkpoint

    from ..engine.checkpoint_check import load_checked_weights
    from ..engine.config_checks import merge_cfg_options
    from ..fileio.checkpoint_schemes import install_checkpoint_loader

    if str(device).startswith('cuda') and not torch.cuda.is_available():
        raise ValueError(f'device {device}: CUDA is not available here; use '
                         'cpu')
    cfg = Config.fromfile(config) if isinstance(config, str) else config
    if cfg_options:
        merge_cfg_options(cfg, cfg_options, cfg_options_raw)
    init_default_scope(cfg.get('default_scope', 'mmdet3d'))
    model = MODELS.build(cfg.model)
    if checkpoint is not None:
        local = '://' not in checkpoint
        if local and not osp.isfile(checkpoint):
            raise FileNotFoundError(f'checkpoint not found: {checkpoint}')
        # Nothing is installed on import: load through the restricted loader.
        install_checkpoint_loader()
        load_checked_weights(
            model, _load_checkpoint(checkpoint, map_location='cpu'),
            checkpoint, cfg.filename, allow_key_mismatch,
            ' Check the config and the checkpoint, or pass '
            '--allow-key-mismatch to use it anyway.',
            'Using it would draw, measure or export a partly random model.')
    model.cfg = cfg
    return model.to(device).eval()


__all__ = ['init_model']
