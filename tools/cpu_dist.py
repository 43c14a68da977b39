"""CPU-only multi-process support for tools/train.py and tools/test.py.

mmengine 0.10.7 assumes CUDA under ``--launcher pytorch``: its
``init_dist`` calls ``torch.cuda.set_device`` and the Runner wraps the model
in DDP with ``device_ids=[LOCAL_RANK]``, which DDP refuses for CPU modules.
These helpers live beside the tools (not in the plugin packages, which the
tools must not import) and do nothing on CUDA machines.
"""
import torch
import torch.distributed as dist
from mmengine.config import Config


def setup_cpu_distributed(cfg: Config) -> None:
    """Initialise the process group for a CPU run and fix DDP's devices.

    The group is initialised with the config's backend (``env_cfg.
    dist_cfg.backend``, gloo by default), so the Runner skips its own
    CUDA-only initialisation, and DDP gets ``device_ids=None``.

    Args:
        cfg (Config): The config after the command-line overrides; its
            ``launcher`` says whether the run is distributed.
    """
    if cfg.launcher == 'none' or torch.cuda.is_available():
        return
    if not dist.is_initialized():
        dist_cfg = cfg.get('env_cfg', {}).get('dist_cfg', {})
        dist.init_process_group(backend=dist_cfg.get('backend', 'gloo'))
    wrapper = cfg.get('model_wrapper_cfg') or dict(
        type='MMDistributedDataParallel',
        broadcast_buffers=False,
        find_unused_parameters=cfg.get('find_unused_parameters', False))
    wrapper['device_ids'] = None
    cfg.model_wrapper_cfg = wrapper


def finalize_distributed() -> None:
    """Destroy the process group after a successful run.

    Without it gloo's threads can abort the process at exit ("terminate
    called without an active exception"); mmengine 0.10.7 never destroys
    the group. The barrier first makes every rank finish its last
    collective before any rank tears its connections down.
    """
    if dist.is_available() and dist.is_initialized():
        dist.barrier()
        dist.destroy_process_group()
