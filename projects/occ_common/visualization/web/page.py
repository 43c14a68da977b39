"""The viewer's HTML page: served (the script by URL) or exported (the
script and the samples inside the one file)."""
import html
import json
from typing import Dict, Optional

STYLE = """
[hidden] { display: none !important; }
body { margin: 0; display: flex; height: 100vh; font: 13px sans-serif;
       color: #222; background: #fff; }
#panel { width: 290px; overflow-y: auto; padding: 8px 10px;
         border-right: 1px solid #ccc; box-sizing: border-box; }
#viewport { flex: 1; position: relative; min-width: 0; }
#viewport canvas { position: absolute; inset: 0; }
#status { position: absolute; left: 8px; bottom: 6px; color: #a00; }
h1 { font-size: 15px; margin: 0 0 4px; }
h2 { font-size: 12px; text-transform: uppercase; color: #666;
     margin: 10px 0 4px; }
section { border-top: 1px solid #eee; }
.row { display: flex; align-items: center; gap: 6px; padding: 1px 0; }
.row.absent .name { color: #aaa; }
.row .count { margin-left: auto; color: #666; font-size: 11px; }
.swatch { width: 12px; height: 12px; border: 1px solid #888;
          display: inline-block; }
.views { display: flex; gap: 8px; }
.views label { white-space: nowrap; }
.flag { display: inline-block; padding: 1px 6px; margin-right: 4px;
        border-radius: 8px; background: #e8e8e8; }
.flag.rain { background: #cfe3ff; } .flag.night { background: #333;
        color: #fff; }
#navigation { display: flex; align-items: center; gap: 4px;
              margin: 6px 0; }
#sample-slider { flex: 1; }
#thumbs { display: grid; grid-template-columns: repeat(3, 1fr); gap: 3px;
          margin-top: 4px; }
#thumbs img { width: 100%; cursor: pointer; }
#readout { white-space: pre-wrap; margin: 0; font-size: 12px; }
select { margin-top: 4px; width: 100%; }
"""

TEMPLATE = """<!DOCTYPE html>
<html lang="en">
<head>
{note}<meta charset="utf-8">
<title>{title}</title>
<style>{style}</style>
</head>
<body data-state="loading">
<div id="panel"></div>
<div id="viewport"><div id="status">loading</div></div>
{embedded}{script}
</body>
</html>
"""


def _inline(text: str) -> str:
    """``text`` safe inside a ``<script>`` element: ``</`` never closes
    it (``<\\/`` means the same in JavaScript strings, regular expressions
    and JSON)."""
    return text.replace('</', '<\\/')


def served_page(title: str) -> str:
    """The page of the server; it fetches ``viewer.js`` and the samples.

    Args:
        title (str): The browser tab's title.

    Returns:
        str: HTML.
    """
    return TEMPLATE.format(
        title=html.escape(title),
        note='',
        style=STYLE,
        embedded='',
        script='<script src="viewer.js"></script>')


def exported_page(title: str, script: str, data: Dict,
                  note: Optional[str] = None) -> str:
    """One self-contained page: the viewer script and the samples inside.

    Args:
        title (str): The browser tab's title.
        script (str): :func:`~.bundle.viewer_script`.
        data (dict): ``meta`` and ``samples`` (each ``message``, the base64
            of the gzip-compressed message, and ``images``, JPEG data
            URLs), read by ``static/main.js``.
        note (str, optional): An HTML comment at the top (what made the
            file). Defaults to None.

    Returns:
        str: HTML that needs no network.
    """
    comment = '' if note is None else \
        f'<!-- {note.replace("--", "- -")} -->\n'
    embedded = ('<script type="application/json" id="occ-embedded">' +
                _inline(json.dumps(data, separators=(',', ':'))) +
                '</script>\n')
    return TEMPLATE.format(
        title=html.escape(title),
        note=comment,
        style=STYLE,
        embedded=embedded,
        script=f'<script>{_inline(script)}</script>')
