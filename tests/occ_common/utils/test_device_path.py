"""Which path a device takes, and the GPU path's chunk sizes
(projects/occ_common/utils/device_path.py)."""
import torch

from projects.occ_common.utils.device_path import (ASSUMED_FREE_BYTES,
                                                   accelerator_path,
                                                   chunk_items,
                                                   forced_accelerator_path)


def test_cpu_tensors_take_the_cpu_path_unless_forced():
    x = torch.zeros(1)
    assert not accelerator_path(x)
    with forced_accelerator_path():
        assert accelerator_path(x)
        with forced_accelerator_path(False):
            assert not accelerator_path(x)
        assert accelerator_path(x)
    assert not accelerator_path(x)


def test_chunk_items():
    """CPU: its own chunk. GPU path forced on the CPU: a quarter of the
    assumed 24 GiB at 1,024 bytes an item = 6 * 2**20 items; a paper-size
    OccCylindrical lift (6 x 50 x 58 x 100 = 1.74 M points of 64 channels
    at 16 bytes each, 1 KiB) fits in one chunk."""
    x = torch.zeros(1)
    assert chunk_items(x, 1024, 16384) == 16384
    with forced_accelerator_path():
        items = chunk_items(x, 1024, 16384)
    assert items == ASSUMED_FREE_BYTES // 4 // 1024 == 6 * 2**20
    assert items >= 6 * 50 * 58 * 100
