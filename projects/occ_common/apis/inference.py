"""A config's model with trained weights, for the analysis tools."""
from typing import Optional, Tuple

from torch import nn


def build_trained_model(config: str,
                        checkpoint: str,
                        cfg_options: Optional[dict] = None,
                        device: str = 'cpu',
                        cfg_options_raw: Optional[dict] = None,
                        allow_key_mismatch: bool = False
                        ) -> Tuple[object, nn.Module]:
    """Build ``config``'s model and load ``checkpoint`` into it.

    The config's ``custom_imports`` register the plugins; the weights come
    through the restricted loader (:func:`install_checkpoint_loader`:
    nothing in the file can run code) and are checked against the model
    as ``tools/test.py`` checks them
    (:func:`~projects.occ_common.engine.hooks.checkpoint_match_hook.load_checked_weights`):
    before, a checkpoint of another model was loaded silently and the
    tools drew or measured a randomly initialised model.

    Args:
        config (str): Config file.
        checkpoint (str): Weights (a Runner checkpoint or a state dict).
        cfg_options (dict, optional): Overrides merged into the config, as
            ``--cfg-options`` gives them, checked by
            :func:`~.config_checks.merge_cfg_options`. Defaults to None.
        device (str): Where the model goes. Defaults to 'cpu'.
        cfg_options_raw (dict, optional): The typed text of each override
            (:class:`~.config_checks.CfgOptionsAction`). Defaults to None.
        allow_key_mismatch (bool): Accept missing, unexpected and reshaped
            keys (they keep their initialisation); non-finite weights are
            refused anyway. Defaults to False.

    Returns:
        tuple: ``(cfg, model)``, the merged config and the model in eval
        mode on ``device``.

    Raises:
        ValueError: If the checkpoint holds no state dict, non-finite
            weights or, unless allowed, keys or shapes other than the
            model's (naming the file and the first mismatched keys).
    """
    from mmengine.config import Config
    from mmengine.registry import MODELS, init_default_scope
    from mmengine.runner.checkpoint import _load_checkpoint

    from ..engine.config_checks import merge_cfg_options
    from ..engine.hooks.checkpoint_match_hook import load_checked_weights
    from ..fileio.checkpoint_schemes import install_checkpoint_loader

    cfg = Config.fromfile(config)
    merge_cfg_options(cfg, cfg_options, cfg_options_raw)
    init_default_scope(cfg.get('default_scope', 'mmdet3d'))
    model = MODELS.build(cfg.model)
    # Nothing is installed on import: load through the restricted loader.
    install_checkpoint_loader()
    load_checked_weights(
        model, _load_checkpoint(checkpoint, map_location='cpu'), checkpoint,
        config, allow_key_mismatch,
        ' Check the config and the checkpoint, or pass '
        '--allow-key-mismatch to use it anyway.',
        'Using it would draw or measure a partly random model.')
    return cfg, model.to(device).eval()
