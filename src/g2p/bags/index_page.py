"""The report's index page (`report/index.html`): the summary, the figures and the animations.

The summary's tables, then each figure with its caption and the animations. Self-contained (inline
style, no scripts, nothing fetched) and linked relatively, so the report directory opens in a browser
wherever it is copied.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from html import escape
from typing import Any

from g2p.bags.summary import Table, summary_tables

_STYLE = """
body { font-family: sans-serif; margin: 2em auto; max-width: 72em; padding: 0 1em; color: #222; }
table { border-collapse: collapse; margin: 0.5em 0 1.5em; font-size: 90%; }
th, td { border: 1px solid #ccc; padding: 0.2em 0.6em; text-align: left; }
th { background: #f0f0f0; }
figure { margin: 1.5em 0; }
figure img, figure video { max-width: 100%; border: 1px solid #ddd; }
figcaption { color: #444; margin-top: 0.3em; }
.skipped { color: #888; }
"""

_LEG_SOURCES = {
    "bag": "the bag's <code>robot_description</code> (the URDF the rig published)",
    "packaged": "the packaged URDF (<code>g2p/description/models/leg.urdf</code>): the bag has no "
    "<code>robot_description</code>",
}


@dataclass(frozen=True)
class IndexEntry:
    """One figure or animation on the page.

    Attributes:
        name: its file name in the report directory (the link target).
        caption: what it shows.
        skipped: why it was not drawn (None: it was, and `name` exists beside the page).
    """

    name: str
    caption: str
    skipped: str | None = None


def index_html(
    summary: Mapping[str, Any], figures: Sequence[IndexEntry], animations: Sequence[IndexEntry] = ()
) -> str:
    """The index page of a report.

    Args:
        summary: the run's summary (g2p.bags.summary.summarize, with the report's keys).
        figures: the figures, in page order.
        animations: the animations (GIF or MP4), shown before the figures.
    """
    run_id = escape(str(summary["run_id"]))
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en">',
        "<head>",
        '<meta charset="utf-8">',
        f"<title>Run {run_id}</title>",
        f"<style>{_STYLE}</style>",
        "</head>",
        "<body>",
        f"<h1>Run {run_id}</h1>",
        '<p>From the bag alone (<code>g2p-report</code>): <a href="../summary.json">summary.json</a>, '
        '<a href="summary.md">summary.md</a>.</p>',
    ]
    source = _LEG_SOURCES.get(str(summary.get("leg_description")))
    if source is not None:
        parts.append(f"<p>The leg is drawn from {source}.</p>")
    parts.append("<h2>Summary</h2>")
    parts += [_table(t) for t in summary_tables(summary)]
    for heading, entries in (("Animations", animations), ("Figures", figures)):
        if entries:
            parts.append(f"<h2>{heading}</h2>")
            parts += [_figure(entry) for entry in entries]
    parts += ["</body>", "</html>"]
    return "\n".join(parts) + "\n"


def _figure(entry: IndexEntry) -> str:
    name, caption = escape(entry.name, quote=True), escape(entry.caption)
    if entry.skipped is not None:
        return f'<p class="skipped"><code>{name}</code>: not drawn ({escape(entry.skipped)}).</p>'
    media = (
        f'<video src="{name}" controls loop></video>'
        if entry.name.endswith(".mp4")
        else f'<a href="{name}"><img src="{name}" alt="{caption}"></a>'
    )
    return f"<figure>{media}<figcaption>{caption} (<code>{name}</code>)</figcaption></figure>"


def _table(table: Table) -> str:
    head = "".join(f"<th>{escape(h)}</th>" for h in table.header)
    body = "\n".join("<tr>" + "".join(f"<td>{escape(c)}</td>" for c in row) + "</tr>" for row in table.rows)
    return f"<table>\n<tr>{head}</tr>\n{body}\n</table>"
