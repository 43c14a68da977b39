"""A LoggerHook whose test-metrics json is written by the main process only.

mmengine 0.10.7's ``LoggerHook.after_test_epoch`` dumps the test record to
``{log_dir}/{timestamp}.json`` from *every* rank, each opening the same
file with ``'w'``. Under ``tools/dist_test.sh`` the ranks hold the same
gathered metrics but different ``time`` / ``data_time``, so their records
differ in length; when the longer one lands first and the shorter one
second, the file keeps the longer record's last byte after the shorter one
and no longer parses (seen in CI: ``{..., "time": 0.0185...}}``). The
training and validation records do not have this problem: they go through
the visualizer, which writes on the main process only.

:class:`MainProcessLoggerHook` writes the test record on the main process
and, on the other ranks, only logs the line, as mmengine does there too.
"""
from typing import Dict, Optional

from mmdet3d.registry import HOOKS
from mmengine.dist import is_main_process
from mmengine.hooks import LoggerHook


@HOOKS.register_module()
class MainProcessLoggerHook(LoggerHook):
    """mmengine's ``LoggerHook`` with one writer of the test json.

    Takes ``LoggerHook``'s arguments unchanged.
    """

    def after_test_epoch(self,
                         runner,
                         metrics: Optional[Dict[str, float]] = None) -> None:
        """Log the test metrics; write the json record on rank 0 only.

        Args:
            runner (Runner): The runner of the test.
            metrics (dict[str, float], optional): The gathered metrics.
        """
        if is_main_process():
            super().after_test_epoch(runner, metrics)
            return
        _, log_str = runner.log_processor.get_log_after_epoch(
            runner, len(runner.test_dataloader), 'test', with_non_scalar=True)
        runner.logger.info(log_str)
