"""The HTML page every report is written into: one self-contained file (styles inline, figures as
data: URLs, a content security policy that allows nothing else), its tables and figures, and the
one escaping function for HTML (``esc``). No run is needed to use it (the fleet report uses it
without loading the calibration path: imucal.fleet.report).
"""
from __future__ import annotations

import base64
import html
import io
import math
from typing import Iterable, Mapping

from imucal import __version__
from imucal.errors import printable

#: No network, no scripts: images only from data: URLs, styles only inline.
CSP = "default-src 'none'; img-src data:; style-src 'unsafe-inline'"

STYLE = """
body{font-family:system-ui,-apple-system,'Segoe UI',Roboto,sans-serif;margin:1.5em auto;max-width:1100px;
     padding:0 1em;color:#1d2125;line-height:1.4}
h1{font-size:1.5em;margin-bottom:.2em} h2{font-size:1.2em;border-bottom:1px solid #ccd;padding-bottom:.2em;
     margin-top:1.6em}
.verdict{border-radius:6px;padding:.8em 1.1em;margin:1em 0;border:2px solid}
.verdict h2{border:none;margin:0 0 .3em 0;font-size:1.35em}
.pass{background:#e8f6ec;border-color:#2e8b57} .check{background:#fff6e0;border-color:#d49a00}
.fail{background:#fdecea;border-color:#c0392b}
td.ok{color:#2e7d32;font-weight:600} td.bad{color:#c0392b;font-weight:600} td.na{color:#777}
table{border-collapse:collapse;margin:.5em 0;font-size:.92em}
th,td{padding:.2em .7em;border-bottom:1px solid #e3e6ea;text-align:left}
td.num,th.num{text-align:right;font-variant-numeric:tabular-nums;font-family:ui-monospace,monospace}
tr.out td{background:#fdecea}
figure{margin:1em 0} figure img{max-width:100%;border:1px solid #e3e6ea}
figcaption{font-size:.9em;color:#555} pre{background:#f6f8fa;padding:.8em;overflow-x:auto;font-size:.85em}
.meta{color:#555;font-size:.9em} ul.warn li{color:#8a5a00}
.scroll{max-width:100%;overflow-x:auto} .sensors{display:flex;flex-wrap:wrap;gap:.8em}
.sensors .verdict{flex:1 1 30em;margin:0;min-width:0} .sensors .verdict h2{font-size:1.05em}
.verdict table{font-size:.88em} .verdict td:first-child{min-width:11em} td.ok,td.bad,td.na{white-space:nowrap}
code,td{overflow-wrap:break-word}
"""


def esc(text: object) -> str:
    """HTML-escaped text (quotes too: safe inside attributes)."""
    return html.escape(printable(str(text), keep="\n\t"), quote=True)


def num(v: float, fmt: str = ".6g") -> str:
    return "n/a" if v is None or not math.isfinite(v) else format(v, fmt)


def table_html(head: Iterable[str], rows: Iterable[Iterable[str]], numeric: Iterable[bool] = (),
           row_class: Iterable[str] = ()) -> str:
    """A table from already-escaped cells."""
    numeric = list(numeric)
    head = list(head)
    cls = [' class="num"' if i < len(numeric) and numeric[i] else "" for i in range(len(head))]
    out = ['<div class="scroll"><table><thead><tr>' + "".join(f"<th{c}>{h}</th>" for c, h in zip(cls, head))
           + "</tr></thead><tbody>"]
    rc = list(row_class)
    for k, r in enumerate(rows):
        attr = f' class="{rc[k]}"' if k < len(rc) and rc[k] else ""
        out.append(f"<tr{attr}>" + "".join(f"<td{c}>{v}</td>" for c, v in zip(cls, r)) + "</tr>")
    out.append("</tbody></table></div>")  # a wide table scrolls inside its box, never widens the page
    return "\n".join(out)


def figures_html(figures: Mapping[str, bytes], captions: Mapping[str, str]) -> str:
    out = []
    for name, png in figures.items():
        data = base64.b64encode(png).decode("ascii")
        cap = captions.get(name, name)
        out.append(f'<figure><img alt="{esc(cap)}" src="data:image/png;base64,{data}">'
                   f"<figcaption>{esc(name)}: {esc(cap)}</figcaption></figure>")
    return "\n".join(out) if out else "<p class=\"meta\">Figures were not made for this run.</p>"


def page_html(title: str, sections: Iterable[tuple[str, str, str]]) -> str:
    """sections: (id, escaped heading, html body)."""
    body = "\n".join(f'<section id="{sid}"><h2>{head}</h2>\n{content}\n</section>' if head else content
                     for sid, head, content in sections)
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<meta http-equiv=\"Content-Security-Policy\" content=\"{CSP}\">"
            "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">"
            f"<title>{esc(title)}</title><style>{STYLE}</style></head>\n<body>\n<h1>{esc(title)}</h1>\n"
            f"{body}\n<p class=\"meta\">imucal {esc(__version__)}</p>\n</body></html>\n")


def render_png(fn, obj) -> bytes:
    """PNG bytes of a figure function ``fn(obj, path_or_file)``."""

    buf = io.BytesIO()
    fn(obj, buf)
    return buf.getvalue()
