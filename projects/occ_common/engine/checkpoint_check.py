"""Refuse weights that are not the model's, or not finite.

mmengine loads a checkpoint non-strictly and only logs the mismatched keys:
a checkpoint of the other model evaluated with exit code 0 and the metric
of a randomly initialised model. :func:`check_checkpoint_state` is the one
check every path that loads a trained model goes through: ``tools/test.py``
and ``tools/train.py`` (:class:`~.hooks.CheckpointMatchHook`) and every
other tool and the demo (:func:`projects.occ_common.apis.init_model`).
"""
from typing import Dict

from ..fileio.state_dict import (key_examples, state_dict_mismatch,
                                 unwrap_state_dict)
from .hooks.non_finite_loss_hook import non_finite_tensors

#: The consequences :func:`check_checkpoint_state` names.
EVALUATE = 'Evaluating it would report a partly random model.'
FINE_TUNE = ('Training from it would start the missing or reshaped parts '
             'from random weights.')
RESUME = ('A run resumes only from a checkpoint of its own model (the '
          'optimizer state would not fit either).')


def check_checkpoint_state(model,
                           state: Dict,
                           source: str,
                           config: str,
                           allow_key_mismatch: bool = False,
                           hint: str = '',
                           consequence: str = EVALUATE) -> Dict:
    """Refuse a state dict with NaN / inf weights or, unless allowed, one
    that is not ``model``'s.

    Shared by :class:`~.hooks.CheckpointMatchHook` (``tools/test.py``,
    ``tools/train.py``) and :func:`load_checked_weights`
    (:func:`projects.occ_common.apis.init_model`).

    Args:
        model (nn.Module): The model the weights are for (not a wrapper).
        state (dict): The checkpoint's ``state_dict``.
        source (str): The checkpoint's name, for the messages.
        config (str): The config's file name, for the messages.
        allow_key_mismatch (bool): Only refuse non-finite weights.
            Defaults to False.
        hint (str): Appended to the key-mismatch message (what the caller
            can do about it). Defaults to ''.
        consequence (str): What using the checkpoint would do, in the
            key-mismatch message. Defaults to :data:`EVALUATE`.

    Returns:
        dict: ``state`` with any ``module.`` prefix removed.

    Raises:
        ValueError: Naming the checkpoint and what is wrong.
    """
    bad = non_finite_tensors(state)
    if bad:
        raise ValueError(
            f'{source} holds non-finite weights: {key_examples(bad)}. It '
            'is the checkpoint of a diverged run; evaluate the last good'
            ' one instead.')
    state = unwrap_state_dict(state, source)
    if allow_key_mismatch:
        return state
    found = state_dict_mismatch(model.state_dict(), state)
    if found:
        raise ValueError(
            f'{source} does not fit the model of {config}: '
            f'{"; ".join(found)}. {consequence}{hint}')
    return state


def load_checked_weights(model,
                         loaded,
                         source: str,
                         config: str,
                         allow_key_mismatch: bool = False,
                         hint: str = '',
                         consequence: str = EVALUATE) -> None:
    """Copy a loaded checkpoint's weights into ``model`` once
    :func:`check_checkpoint_state` accepts them.

    For :func:`projects.occ_common.apis.init_model`, which every tool and
    the demo load a trained model with: mmdet3d's ``init_model``, with
    ``tools/test.py``'s checks.

    Args:
        model (nn.Module): The model the weights are for.
        loaded (object): What the checkpoint file held: a Runner
            checkpoint (``dict(state_dict=...)``) or a bare state dict.
        source, config, allow_key_mismatch, hint, consequence: As for
            :func:`check_checkpoint_state`.

    Raises:
        ValueError: If ``loaded`` holds no state dict, or
            :func:`check_checkpoint_state` refuses it.
    """
    state = check_checkpoint_state(model, unwrap_state_dict(loaded, source),
                                   source, config,
                                   allow_key_mismatch, hint, consequence)
    model.load_state_dict(state, strict=False)  # num_batches_tracked


__all__ = [
    'EVALUATE', 'FINE_TUNE', 'RESUME', 'check_checkpoint_state',
    'load_checked_weights'
]
