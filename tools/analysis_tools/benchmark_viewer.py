#!/usr/bin/env python
"""Bytes sent per sample and time until the scene shows, in the 3D viewer.

Serves the samples of ``tools/misc/browse_occ.py``'s command line (same
arguments) on a free port of 127.0.0.1, opens the page in headless Chromium
(software WebGL: a lower bound of a laptop's browser) and loads each
sample ``--rounds`` times in alternating order, reporting per sample:

- the message's bytes, raw and gzip-compressed (what the server sends),
  and the camera JPEGs';
- the time from asking for the sample to the first frame that shows it
  (``fetch`` + decode + building the instances + drawing), its median over
  the rounds (the first load of a sample also encodes it on the server:
  that round is reported apart, as ``first``);
- the size of the one-file export of the first sample.

Example::

    python tools/analysis_tools/benchmark_viewer.py CONFIG \\
        --checkpoint CKPT --samples 0 1 2 --rounds 3 --out viewer.json
"""
import argparse
import json
import os.path as osp
import statistics
import sys
import tempfile
import time

from projects.occ_common.analysis.headless_chromium import HeadlessChromium
from projects.occ_common.analysis.tool_runs import load_tool
from projects.occ_common.visualization.web import (ViewerServer, export_html,
                                                   viewer_meta, viewer_script)


def parse_args(argv=None):
    """This tool's options, then browse_occ.py's."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--samples', type=int, nargs='+', default=[0])
    parser.add_argument('--rounds', type=int, default=3)
    parser.add_argument('--size', type=int, nargs=2, default=(1280, 800),
                        help='browser viewport (W, H)')
    parser.add_argument('--out', help='also write the report as JSON')
    return parser.parse_known_args(argv)


def load_in_page(browser: HeadlessChromium, index: int) -> dict:
    """Load sample ``index`` in the open page; its timings."""
    return browser.evaluate(
        f'window.occViewer.load({index}).then(() => '
        'window.occViewer.timings)')


def main(argv=None) -> dict:
    """Run the measurement; returns (and prints) the report."""
    args, browse_argv = parse_args(argv)
    browse = load_tool('tools/misc/browse_occ.py')
    browse_args = browse.parse_args(browse_argv)
    with tempfile.TemporaryDirectory() as tmp:
        samples = browse.build_samples(browse_args, tmp)
        browse.check_indices(args.samples, len(samples), 'the dataset')
        script = viewer_script()
        meta = viewer_meta(samples.class_names, samples.empty_label,
                           len(samples), initial_index=args.samples[0])
        server = ViewerServer(meta, samples.encode, script, port=0)
        server.start_background()
        times = {index: [] for index in args.samples}
        first = {}
        try:
            with HeadlessChromium(*args.size, timeout=600) as browser:
                started = time.perf_counter()
                browser.navigate(server.url)
                state = browser.wait_for(
                    'document.body.dataset.state !== "loading" && '
                    'document.body.dataset.state', timeout=600)
                if state != 'ready':
                    raise RuntimeError(browser.evaluate(
                        'document.getElementById("status").textContent'))
                page_ms = (time.perf_counter() - started) * 1e3
                for round_ in range(args.rounds + 1):
                    order = args.samples if round_ % 2 == 0 else \
                        args.samples[::-1]
                    for index in order:
                        shown = load_in_page(browser, index)['shownMs']
                        if index not in first:
                            first[index] = shown
                        else:
                            times[index].append(shown)
                errors = browser.page_errors()
        finally:
            server.shutdown()
            server.server_close()
        export = export_html(osp.join(tmp, 'sample.html'), meta,
                             [samples.encode(args.samples[0])], script)
    report = dict(
        config=browse_args.config,
        viewport=list(args.size),
        page_load_ms=round(page_ms),
        script_bytes=len(script.encode()),
        samples={
            index: dict(server.cache.sizes[index],
                        first_ms=round(first[index]),
                        shown_ms=round(statistics.median(times[index]))
                        if times[index] else None)
            for index in args.samples
        },
        export_bytes=export,
        page_errors=errors)
    text = json.dumps(report, indent=2)
    print(text)
    if args.out:
        with open(args.out, 'w') as f:
            f.write(text + '\n')
    return report


if __name__ == '__main__':
    sys.exit(0 if main() is not None else 1)
