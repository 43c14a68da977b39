"""Checkpoint metadata is data: config text never reaches mmengine.

A checkpoint's strings are plain data to the restricted unpickler, but
mmengine runs some of them as Python: ``Runner.resume`` passes
``checkpoint['meta']['config']`` (the key of mmcv-era checkpoints) to
``Config.fromstring(..., '.py')``, which executes it, and its inferencers
do the same with ``meta['cfg']`` and ``message_hub['runtime_info']['cfg']``
(the config text every mmengine Runner checkpoint carries). A genuine
checkpoint with a one-line payload in ``meta['config']`` ran it through
``tools/train.py --resume``, exit 0.

:func:`drop_config_text` removes those entries from every checkpoint the
restricted loader returns (:func:`~.safe_pickle.load_checkpoint_stream`),
before any caller sees it. Nothing in mmengine's training or testing needs
them: ``Runner.resume`` only compares the ``gpu_ids`` of ``meta['config']``
with the current world size (the ``auto_scale_lr`` check), and the config
of a resumed run is the one it was started with (its ``runtime_info.cfg``
is then the current one, which the next checkpoint saves). The files on
disk keep the text; read it with ``torch.load`` yourself if you trust the
file.
"""
import warnings
from typing import Any, List, Tuple

#: Entries whose value mmengine runs as a Python config, and the reader.
CONFIG_TEXT_KEYS: Tuple[Tuple[Tuple[str, ...], str], ...] = (
    (('meta', 'config'), 'Runner.resume'),
    (('meta', 'cfg'), 'the inferencers'),
    (('message_hub', 'runtime_info', 'cfg'), 'the inferencers'),
)


def drop_config_text(checkpoint: Any, name: str) -> List[str]:
    """Remove every :data:`CONFIG_TEXT_KEYS` entry of ``checkpoint``.

    ``meta['config']`` is written by mmcv's runners only, never by
    mmengine's: finding it is reported with a warning naming the file.
    The others are in every mmengine checkpoint and go silently.

    Args:
        checkpoint (Any): A loaded checkpoint (changed in place); anything
            but a dict is left alone.
        name (str): The file, for the warning.

    Returns:
        list[str]: The dotted keys removed (``'meta.config'`` ...).
    """
    removed = []
    for keys, reader in CONFIG_TEXT_KEYS:
        node = checkpoint
        for key in keys[:-1]:
            node = node.get(key) if isinstance(node, dict) else None
        if not isinstance(node, dict) or keys[-1] not in node:
            continue
        del node[keys[-1]]
        dotted = '.'.join(keys)
        removed.append(dotted)
        if dotted == 'meta.config':
            warnings.warn(
                f'checkpoint {name}: ignoring its meta.config (config text '
                f'of an mmcv-era runner), which {reader} would run as '
                'Python code.')
    return removed


__all__ = ['CONFIG_TEXT_KEYS', 'drop_config_text']
