"""Forming the process group with a deadline: a missing peer is named.

``init_process_group`` waits for every rank for the process group's
timeout, 30 minutes by default, and says nothing meanwhile: a node that
never started (a wrong ``NODE_RANK``, a crashed rank, a firewall) left the
others waiting silently. Passing a shorter ``timeout`` would also shorten
every collective of the run (a long evaluation on rank 0 would then kill
the others). :func:`rendezvous_deadline` instead watches the forming only:
if the group is not formed after ``INIT_TIMEOUT`` seconds, the rank prints
one line naming itself, the world size and the rendezvous address, and
exits with status 1 (under torchrun the agent then stops the other ranks).

The deadline is :data:`DEFAULT_INIT_TIMEOUT` seconds, or the
``OCC_DIST_INIT_TIMEOUT`` environment variable (seconds; 0 waits as long
as torch does). Ten minutes is torchrun's own default rendezvous join
timeout: nodes of one job that start further apart than that are not
expected.
"""
import contextlib
import os
import threading
from typing import Iterator, Optional

#: Seconds a rank waits for the process group to form.
DEFAULT_INIT_TIMEOUT = 600.0
#: The environment variable overriding it.
INIT_TIMEOUT_ENV = 'OCC_DIST_INIT_TIMEOUT'


def init_timeout() -> float:
    """The deadline in seconds (0: none).

    Raises:
        ValueError: If ``OCC_DIST_INIT_TIMEOUT`` is not a number >= 0.
    """
    text = os.environ.get(INIT_TIMEOUT_ENV)
    if text is None:
        return DEFAULT_INIT_TIMEOUT
    try:
        value = float(text)
    except ValueError:
        value = -1.0
    if value < 0:
        raise ValueError(f'{INIT_TIMEOUT_ENV}={text!r}: expected seconds '
                         '(a number >= 0; 0 waits as long as torch does)')
    return value


def _who_and_where() -> str:
    """``rank R of W`` and the rendezvous address, from the environment."""
    env = os.environ
    rank = env.get('RANK', env.get('SLURM_PROCID', '?'))
    world = env.get('WORLD_SIZE', env.get('SLURM_NTASKS', '?'))
    address = f'{env.get("MASTER_ADDR", "?")}:{env.get("MASTER_PORT", "?")}'
    return f'rank {rank} of {world}', address


def missing_peer_message(timeout: float) -> str:
    """The line a rank prints when the group has not formed in time."""
    who, address = _who_and_where()
    return (f'{who}: the process group at {address} did '
            f'not form within {timeout:g} s: a peer is missing (did every '
            'node start, with its own NODE_RANK and the same MASTER_ADDR, '
            f'MASTER_PORT and world size?). Set {INIT_TIMEOUT_ENV}=SECONDS '
            'to wait longer.')


@contextlib.contextmanager
def rendezvous_deadline(timeout: Optional[float] = None) -> Iterator[None]:
    """Exit this rank if the block (forming the group) outlasts ``timeout``.

    Args:
        timeout (float, optional): Seconds; 0 for none. Defaults to
            :func:`init_timeout`.

    Yields:
        None: Initialise the process group in the block.
    """
    timeout = init_timeout() if timeout is None else timeout
    done = threading.Event()

    def watch():
        if not done.wait(timeout):
            # To the descriptor itself: sys.stderr may be a wrapper that
            # os._exit would not flush (a launcher's, pytest's capture).
            os.write(2, f'error: {missing_peer_message(timeout)}\n'.encode())
            os._exit(1)  # the main thread is stuck inside torch's C++

    if timeout > 0:
        threading.Thread(target=watch, name='rendezvous deadline',
                         daemon=True).start()
    try:
        yield
    except (RuntimeError, OSError) as err:
        # torch's own failures (an address in use, a refused connection:
        # DistNetworkError is a RuntimeError) named neither the rank nor
        # the rendezvous address.
        who, address = _who_and_where()
        raise RuntimeError(f'{who}: could not form the process group at '
                           f'{address}: {err}') from err
    finally:
        done.set()


__all__ = [
    'DEFAULT_INIT_TIMEOUT', 'INIT_TIMEOUT_ENV', 'init_timeout',
    'missing_peer_message', 'rendezvous_deadline'
]
