"""What a conversion skipped, reported once at its end.

The converters stop on what makes a sample unusable (a missing key frame
or image) and go on, recording it here, where the rest stays correct:

* **missing sweeps** (a keyframe-only download): the sample links the
  sweeps up to the first missing one (possibly none). Safe: the sweeps it
  keeps are real and in order; the model sees fewer points.
* **a missing occupancy label**: that format's path is None for the
  sample. Safe: training drops it (``filter_empty_gt``), evaluation stops
  on it with an error naming the sample, so no score is computed on a
  silently smaller split.
* **a missing lidarseg label**: the path is None. Safe: only SDG-OCC's 2-D
  targets use it, and they come from the occupancy labels instead.
* **a nuScenes-lidarseg / -panoptic table without its label files**
  (``panoptic.json`` unpacked without ``panoptic/``): the table is hidden
  from nuscenes-devkit (lidarseg: its records without a file). Safe:
  panoptic is never read; lidarseg as above.
"""
import warnings
from collections import OrderedDict
from typing import List


class ConversionReport:
    """Problems grouped by kind, each with the samples / files it hit."""

    def __init__(self) -> None:
        self.items = OrderedDict()

    def add(self, kind: str, detail: str) -> None:
        """Record one occurrence of ``kind`` (e.g. one sample's file); the
        same detail twice (a sample in two splits) counts once."""
        self.items.setdefault(kind, OrderedDict())[detail] = None

    def extend(self, other: 'ConversionReport') -> None:
        """Merge the records of another report (e.g. of a worker)."""
        for kind, details in other.items.items():
            for detail in details:
                self.add(kind, detail)

    def lines(self, examples: int = 3) -> List[str]:
        """One line per kind: its count and the first ``examples``."""
        out = []
        for kind, details in self.items.items():
            first = list(details)[:examples]
            more = '; ...' if len(details) > examples else ''
            out.append(f'{kind}: {len(details)} ({"; ".join(first)}{more})')
        return out

    def emit(self, where: str) -> None:
        """Print the report and warn once per kind (nothing if clean)."""
        if not self.items:
            return
        print(f'{where}: converted, with these problems (see '
              'projects/occ_common/datasets/converters/report.py):')
        for line in self.lines():
            print(f'  {line}')
            warnings.warn(f'{where}: {line}')
