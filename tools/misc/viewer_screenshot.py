#!/usr/bin/env python
"""A PNG of the 3D viewer (a served URL or an exported file), taken in
headless Chromium; how the pictures of docs/visualization.md were made.

Example::

    python tools/misc/viewer_screenshot.py scene.html out.png \\
        --view errors --points class --camera -60 0 40 0 0 0
"""
import argparse
import os.path as osp

import numpy as np
from PIL import Image

from projects.occ_common.analysis.headless_chromium import HeadlessChromium


def parse_args(argv=None):
    """Parse the command line."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('page', help='http://... URL or an exported .html')
    parser.add_argument('out', help='PNG file to write')
    parser.add_argument('--sample', type=int, help='sample to load first')
    parser.add_argument('--view', choices=['gt', 'pred', 'errors'])
    parser.add_argument('--mask', choices=['none', 'camera', 'lidar'])
    parser.add_argument('--points',
                        choices=['off', 'height', 'intensity', 'class'])
    parser.add_argument('--hide-classes', type=int, nargs='+', default=[],
                        metavar='LABEL')
    parser.add_argument('--no-frusta', action='store_true')
    parser.add_argument('--camera', type=float, nargs=6,
                        metavar=('X', 'Y', 'Z', 'TX', 'TY', 'TZ'),
                        help='camera position and target, grid frame (m)')
    parser.add_argument('--size', type=int, nargs=2, default=(1280, 800),
                        metavar=('W', 'H'))
    parser.add_argument('--colours', type=int, default=256,
                        help='quantise the PNG to this many colours (keeps '
                        'it small); 0 keeps full colour')
    return parser.parse_args(argv)


def main(argv=None) -> str:
    """Take the screenshot; returns the PNG's path."""
    args = parse_args(argv)
    url = args.page if '://' in args.page else \
        'file://' + osp.abspath(args.page)
    actions = []
    if args.sample is not None:
        actions.append(f'window.occViewer.load({args.sample})')
    if args.view:
        actions.append(f'window.occViewer.setView("{args.view}")')
    if args.mask:
        actions.append(f'window.occViewer.setMask("{args.mask}")')
    if args.points:
        actions.append(f'window.occViewer.setPoints("{args.points}")')
    actions += [f'window.occViewer.setClassVisible({label}, false)'
                for label in args.hide_classes]
    if args.no_frusta:
        actions.append('window.occViewer.setFrusta(false)')
    if args.camera:
        position, target = args.camera[:3], args.camera[3:]
        actions.append(f'window.occViewer.scene.setCamera({position}, '
                       f'{target})')
    with HeadlessChromium(*args.size, timeout=600) as browser:
        browser.navigate(url)
        state = browser.wait_for(
            'document.body.dataset.state !== "loading" && '
            'document.body.dataset.state', timeout=600)
        if state != 'ready':
            raise RuntimeError(f'{url}: ' + browser.evaluate(
                'document.getElementById("status").textContent'))
        for action in actions:
            browser.evaluate(action)
        browser.evaluate('window.occViewer.drawn()')
        # Camera images are textures loaded after the first frame.
        browser.wait_for('[...document.images].every(i => i.complete)')
        browser.evaluate('window.occViewer.drawn()')
        errors = browser.page_errors()
        if errors:
            raise RuntimeError(f'{url}: {errors}')
        image = Image.fromarray(np.ascontiguousarray(browser.screenshot()))
    if args.colours:
        image = image.quantize(args.colours, method=Image.Quantize.MEDIANCUT)
    image.save(args.out, optimize=True)
    print(f'wrote {args.out}')
    return args.out


if __name__ == '__main__':
    main()
