"""The command-line reference, generated from the parser the command itself runs.

``.. cli-help::`` (``{cli-help}`` in MyST) walks :func:`napari_swa_imesh.cli.build_parser`
and writes one section per sub-command holding exactly what ``swa-imesh COMMAND --help``
prints (at a fixed width of 88 columns, so the page does not depend on the terminal that
builds it). Help strings are shown as text, never parsed as markup: an option's help that
mentions ``*HEAT TRANSFER`` or ``interface_*`` stays as written.
"""

from __future__ import annotations

import os

from docutils import nodes
from sphinx.application import Sphinx
from sphinx.util.docutils import SphinxDirective


def _help(parser) -> str:
    previous = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = "88"          # argparse wraps at $COLUMNS - 2
    try:
        return parser.format_help()
    finally:
        if previous is None:
            os.environ.pop("COLUMNS", None)
        else:
            os.environ["COLUMNS"] = previous


class CliHelp(SphinxDirective):
    has_content = False

    def run(self) -> list[nodes.Node]:
        from napari_swa_imesh.cli import build_parser

        parser = build_parser()
        out: list[nodes.Node] = [nodes.literal_block(text=_help(parser), language="text")]
        sub = next(a for a in parser._actions if a.dest == "command")
        for name, command in sub.choices.items():
            title = f"swa-imesh {name}"
            section = nodes.section(ids=[nodes.make_id(title)],
                                    names=[nodes.fully_normalize_name(title)])
            section += nodes.title(text=title)
            section += nodes.literal_block(text=_help(command), language="text")
            self.state.document.note_implicit_target(section)
            out.append(section)
        return out


def setup(app: Sphinx) -> dict:
    app.add_directive("cli-help", CliHelp)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
