"""Process groups of tools/train.py and tools/test.py, on CPU and CUDA.

mmengine 0.10.7 assumes CUDA under ``--launcher pytorch``: its
``init_dist`` calls ``torch.cuda.set_device`` and the Runner wraps the model
in DDP with ``device_ids=[LOCAL_RANK]``, which DDP refuses for CPU modules;
the CPU path here uses gloo and no device ids. On every device the group
forms under a deadline (:mod:`.dist_rendezvous`). These helpers live in the
package (not beside the tools) so that the tools import them like any
installed module, whatever the working directory; the models still come
from each config's ``custom_imports``.
"""
import logging
import os
import sys

import torch
import torch.distributed as dist
from mmengine.config import Config

from .dist_rendezvous import rendezvous_deadline

#: Backends that need CUDA devices; a CPU run uses gloo in their place.
CUDA_ONLY_BACKENDS = ('nccl', )


def cpu_backend(dist_cfg: dict) -> str:
    """The process-group backend of a run without CUDA.

    The configs name nccl, the backend for GPUs (mmdet3d's default); nccl
    cannot run on the CPU, so a CPU run takes gloo. Another backend a
    config names (gloo, mpi) is kept.

    Args:
        dist_cfg (dict): The config's ``env_cfg.dist_cfg``.

    Returns:
        str: ``'gloo'`` for a missing or CUDA-only backend, else the
        config's.
    """
    backend = dist_cfg.get('backend') or 'gloo'
    return 'gloo' if backend in CUDA_ONLY_BACKENDS else backend


def setup_distributed(cfg: Config) -> None:
    """Form the process group before the Runner is built; fix DDP's
    devices on the CPU.

    The group forms under a deadline (:mod:`.dist_rendezvous`): a rank
    whose peers do not all arrive exits naming itself and the address
    instead of waiting silently. On a CUDA machine mmengine's
    ``init_dist`` initialises the config's ``env_cfg.dist_cfg`` (nccl),
    as the Runner would (it then skips its own). Without CUDA the group
    uses :func:`cpu_backend` of it (gloo in place of nccl), and DDP gets
    ``device_ids=None``.

    Args:
        cfg (Config): The config after the command-line overrides; its
            ``launcher`` says whether the run is distributed.
    """
    if cfg.launcher == 'none':
        return
    dist_cfg = dict(cfg.get('env_cfg', {}).get('dist_cfg', {}))
    if torch.cuda.is_available():
        if not dist.is_initialized():
            from mmengine.dist import init_dist
            with rendezvous_deadline():
                init_dist(cfg.launcher, **dist_cfg)
        return
    if not dist.is_initialized():
        with rendezvous_deadline():
            dist.init_process_group(backend=cpu_backend(dist_cfg))
    wrapper = cfg.get('model_wrapper_cfg') or dict(
        type='MMDistributedDataParallel',
        broadcast_buffers=False,
        find_unused_parameters=cfg.get('find_unused_parameters', False))
    wrapper['device_ids'] = None
    cfg.model_wrapper_cfg = wrapper


#: The name of :func:`setup_distributed` in earlier versions (it then
#: formed CPU groups only).
setup_cpu_distributed = setup_distributed


def finalize_distributed() -> None:
    """End a successful distributed run without gloo's exit-time abort.

    At interpreter exit, objects that still hold the gloo process group
    (mmengine's DDP wrapper does) are destroyed during C++ static
    teardown, and gloo can then abort the process ("terminate called
    without an active exception", SIGABRT) after all work succeeded.
    Destroying the group after a barrier made that rarer but not gone
    (1 in 5 runs on a loaded machine), so on CPU runs the process then
    exits with ``os._exit(0)`` after flushing its output: every
    checkpoint and log is already closed (checkpoints are written
    atomically and fsynced), and no exit-time destructor runs. CUDA runs
    exit normally.
    """
    if not (dist.is_available() and dist.is_initialized()):
        return
    dist.barrier()
    dist.destroy_process_group()
    if torch.cuda.is_available():
        return
    logging.shutdown()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(0)
