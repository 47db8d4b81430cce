"""The report as a PDF for review and sign-off (matplotlib's PDF backend, no other dependency).

:func:`write_pdf` lays out A4 portrait pages with :class:`matplotlib.figure.Figure` objects
and writes them with :class:`matplotlib.backends.backend_pdf.PdfPages`:

1. the headline and the verdict box with its checks, and what was studied;
2. the sampled inputs (tolerances and the initial gap) and the assumptions table, with where
   each comes from, and the results at a glance;
3. in a study with a ``[carriage]``, the carriage section (load case, preload, tracks with
   the nominal load distribution and its figure, displacement and stiffness, solved
   carriages), then the sections of the HTML report with their figures and captions and
   the tables below them (the quality table and the linear stack-up, the ranked Sobol'
   tables, the spot-check status); in a study with ``[contact]`` the section "What contact
   costs" takes the place of its figure (its paragraphs, tables and notes around the
   friction figure);
4. the provenance (the result file's global attributes), then the review and sign-off
   block: prepared by / reviewed by / approved by, each with name, function, date and a
   signature line, the decision, comments, and the SHA-256 of the result file that the
   signatures refer to.

The HTML page shows besides only the config's TOML text and, in a study with a rare-event
estimator, its tables (README "Handing on a study").

Text is wrapped to measured widths (Agg text metrics), so long values never run over a
column; every page carries the report's identity and "page i of n" in its footer.
"""

import functools
import hashlib
import io
import os
from dataclasses import dataclass, field

import matplotlib
import matplotlib.image
from matplotlib.backends.backend_agg import RendererAgg
from matplotlib.backends.backend_pdf import PdfPages
from matplotlib.font_manager import FontProperties
from matplotlib.lines import Line2D
from matplotlib.patches import Rectangle

from tolsim import __version__
from tolsim.reports.style import RC, new_canvas
from tolsim.reports.verdict import STATUS_LABELS

#: A4 portrait [in].
PAGE_WIDTH, PAGE_HEIGHT = 8.27, 11.69
#: Page margin [in].
MARGIN = 0.6
#: Resolution of the figures embedded in the PDF [dots per inch].
FIGURE_DPI = 180
STATUS_COLOURS = {"pass": "#007700", "fail": "#bb0000", "undecided": "#cc8800"}
_RENDERER = RendererAgg(10, 10, 72)  # text metrics in points


def file_sha256(path) -> str:
    """SHA-256 (hex) of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


@functools.lru_cache(maxsize=64)
def _font(size, weight):
    return FontProperties(family=RC.get("font.family", "sans-serif"), size=size, weight=weight)


@functools.lru_cache(maxsize=65536)
def _width(text, size, weight="normal"):
    """Width of one line of text [in] (Agg metrics)."""
    w, _, _ = _RENDERER.get_text_width_height_descent(text, _font(size, weight), ismath=False)
    return w / 72.0


def wrap(text, width, size, weight="normal") -> list:
    """Greedy word wrap of ``text`` to ``width`` [in] at font ``size`` [pt]; lines."""
    lines = []
    for paragraph in str(text).split("\n"):
        words = paragraph.split(" ")
        line = ""
        for word in words:
            trial = f"{line} {word}" if line else word
            if line and _width(trial, size, weight) > width:
                lines.append(line)
                line = word
            else:
                line = trial
            while _width(line, size, weight) > width and len(line) > 1:  # one long word
                cut = len(line) - 1
                while cut > 1 and _width(line[:cut], size, weight) > width:
                    cut -= 1
                # prefer to break after an underscore, a dot or a slash (names, paths)
                soft = max(line.rfind(sep, 0, cut) for sep in "_./")
                cut = soft + 1 if soft > 0 else cut
                lines.append(line[:cut])
                line = line[cut:]
        lines.append(line)
    return lines


@dataclass
class _Page:
    """One A4 page being laid out top-down; ``y`` is the cursor from the top [in]."""

    fig: object
    y: float = MARGIN
    footer: list = field(default_factory=list)

    @property
    def room(self):
        return PAGE_HEIGHT - MARGIN - 0.35 - self.y

    def text(self, x, y, s, size=9.0, **kw):
        """Text at (x, y) inches from the top left, anchored at its top left."""
        self.fig.text(x / PAGE_WIDTH, 1 - y / PAGE_HEIGHT, s, fontsize=size, va="top",
                      ha=kw.pop("ha", "left"), **kw)


class _Document:
    """Pages laid out in order; a new page when the next block does not fit."""

    def __init__(self, title):
        self.title = title
        self.pages = []
        self.new_page()

    def new_page(self):
        with matplotlib.rc_context(RC):
            fig = new_canvas(PAGE_WIDTH, PAGE_HEIGHT)
        fig.set_layout_engine(None)
        self.page = _Page(fig)
        self.pages.append(self.page)
        return self.page

    def ensure(self, height):
        if self.page.room < height:
            self.new_page()

    def heading(self, text, size=13.0):
        self.ensure(0.9)
        self.page.y += 0.12
        self.page.text(MARGIN, self.page.y, text, size=size, weight="bold")
        self.page.y += size / 72 * 1.5

    def paragraph(self, text, size=9.0, colour="0.15", weight="normal", indent=0.0):
        width = PAGE_WIDTH - 2 * MARGIN - indent
        step = size / 72 * 1.32
        for line in wrap(text, width, size, weight):
            self.ensure(step)
            self.page.text(MARGIN + indent, self.page.y, line, size=size, color=colour,
                           weight=weight)
            self.page.y += step
        self.page.y += 0.06

    def table(self, header, rows, widths, size=7.8, header_fill="#eeeeee", colours=None):
        """A table with wrapped cells; ``widths`` are fractions of the text width. A table
        that runs over a page continues on the next with its header repeated."""
        total = PAGE_WIDTH - 2 * MARGIN
        cols = [w * total for w in widths]
        pad = 0.05
        step = size / 72 * 1.28

        def cells(row, weight):
            return [wrap(c, cw - 2 * pad, size, weight) for c, cw in zip(row, cols,
                                                                         strict=True)]

        def draw(row, fill, weight, colour_row=None):
            wrapped = cells(row, weight)
            height = max(len(c) for c in wrapped) * step + 2 * pad
            x = MARGIN
            fig = self.page.fig
            for j, (lines, cw) in enumerate(zip(wrapped, cols, strict=True)):
                fig.add_artist(Rectangle(
                    (x / PAGE_WIDTH, 1 - (self.page.y + height) / PAGE_HEIGHT),
                    cw / PAGE_WIDTH, height / PAGE_HEIGHT, transform=fig.transFigure,
                    facecolor=fill or "none", edgecolor="0.6", lw=0.5))
                colour = (colour_row or {}).get(j, "0.1")
                for i, line in enumerate(lines):
                    self.page.text(x + pad, self.page.y + pad + i * step, line, size=size,
                                   weight=weight, color=colour)
                x += cw
            self.page.y += height

        def height_of(row, weight):
            return max(len(c) for c in cells(row, weight)) * step + 2 * pad

        self.ensure(height_of(header, "bold") + (height_of(rows[0], "normal") if rows else 0))
        draw(header, header_fill, "bold")
        for k, row in enumerate(rows):
            if self.page.room < height_of(row, "normal"):
                self.new_page()
                draw(header, header_fill, "bold")
            draw(row, None, "normal", colours[k] if colours else None)
        self.page.y += 0.15

    def image(self, png, caption, size=8.0, heading=None, heading_size=11.5):
        """A PNG at the text width (scaled down to fit a page) with its caption below, and
        a heading above it kept on the same page."""
        img = matplotlib.image.imread(io.BytesIO(png), format="png")
        h_px, w_px = img.shape[:2]
        width = PAGE_WIDTH - 2 * MARGIN
        cap_lines = wrap(caption, width, size)
        cap_height = len(cap_lines) * size / 72 * 1.3 + 0.1
        head = 0.12 + heading_size / 72 * 1.5 if heading else 0.0
        height = width * h_px / w_px
        limit = PAGE_HEIGHT - 2 * MARGIN - 0.6 - cap_height - head
        if height > limit:
            width, height = width * limit / height, limit
        self.ensure(head + height + cap_height + 0.1)
        if heading:
            self.heading(heading, size=heading_size)
        fig = self.page.fig
        ax = fig.add_axes([MARGIN / PAGE_WIDTH, 1 - (self.page.y + height) / PAGE_HEIGHT,
                           width / PAGE_WIDTH, height / PAGE_HEIGHT])
        ax.imshow(img, interpolation="none", aspect="auto")
        ax.set_axis_off()
        self.page.y += height + 0.06
        for line in cap_lines:
            self.page.text(MARGIN, self.page.y, line, size=size, color="0.35")
            self.page.y += size / 72 * 1.3
        self.page.y += 0.2

    def box(self, label, colour, lines, size=9.5):
        """A framed box: a large label and wrapped lines (the verdict)."""
        width = PAGE_WIDTH - 2 * MARGIN
        wrapped = [wrap(s, width - 0.3, size) for s in lines]
        step = size / 72 * 1.35
        height = 0.55 + sum(len(w) for w in wrapped) * step + 0.05 * len(lines) + 0.12
        self.ensure(height)
        fig = self.page.fig
        fig.add_artist(Rectangle(
            (MARGIN / PAGE_WIDTH, 1 - (self.page.y + height) / PAGE_HEIGHT),
            width / PAGE_WIDTH, height / PAGE_HEIGHT, transform=fig.transFigure,
            facecolor=colour, alpha=0.07, edgecolor="none"))
        fig.add_artist(Rectangle(
            (MARGIN / PAGE_WIDTH, 1 - (self.page.y + height) / PAGE_HEIGHT),
            width / PAGE_WIDTH, height / PAGE_HEIGHT, transform=fig.transFigure,
            facecolor="none", edgecolor=colour, lw=2.5))
        y = self.page.y + 0.14
        self.page.text(MARGIN + 0.15, y, label, size=17, weight="bold", color=colour)
        y += 0.41
        for block in wrapped:
            for line in block:
                self.page.text(MARGIN + 0.15, y, line, size=size)
                y += step
            y += 0.05
        self.page.y += height + 0.2

    def finish(self, footer):
        n = len(self.pages)
        for i, page in enumerate(self.pages, 1):
            page.text(MARGIN, PAGE_HEIGHT - MARGIN + 0.05, footer, size=7, color="0.45")
            page.text(PAGE_WIDTH - MARGIN, PAGE_HEIGHT - MARGIN + 0.05, f"page {i} of {n}",
                      size=7, color="0.45", ha="right")
            page.fig.add_artist(Line2D(
                [MARGIN / PAGE_WIDTH, 1 - MARGIN / PAGE_WIDTH],
                [1 - (PAGE_HEIGHT - MARGIN) / PAGE_HEIGHT] * 2, color="0.7", lw=0.5))


def _sign_off(doc, sha, roles, fields, decisions):
    doc.heading("Review and sign-off")
    doc.paragraph("By signing, each person confirms the role stated for the result file "
                  f"with SHA-256 {sha} and for the verdict, assumptions and figures of this "
                  "report made from it.", size=8.5)
    total = PAGE_WIDTH - 2 * MARGIN
    row_h = 0.95
    doc.ensure(len(roles) * (row_h + 0.1) + 2.6)
    page = doc.page
    for role in roles:
        page.text(MARGIN, page.y, role, size=10.5, weight="bold")
        y = page.y + 0.28
        x = MARGIN
        width = total / len(fields)
        for f in fields:
            page.text(x, y + 0.5, f, size=7.5, color="0.4")
            page.fig.add_artist(Line2D(
                [x / PAGE_WIDTH, (x + width - 0.2) / PAGE_WIDTH],
                [1 - (y + 0.45) / PAGE_HEIGHT] * 2, color="0.2", lw=0.7))
            x += width
        page.y += row_h + 0.1
    page.y += 0.1
    page.text(MARGIN, page.y, "Decision:", size=10, weight="bold")
    x = MARGIN + 1.0
    for d in decisions:
        page.fig.add_artist(Rectangle(
            (x / PAGE_WIDTH, 1 - (page.y + 0.15) / PAGE_HEIGHT), 0.14 / PAGE_WIDTH,
            0.14 / PAGE_HEIGHT, transform=page.fig.transFigure, facecolor="none",
            edgecolor="0.2", lw=0.8))
        page.text(x + 0.22, page.y + 0.01, d, size=9.5)
        x += 0.45 + _width(d, 9.5)
    page.y += 0.45
    page.text(MARGIN, page.y, "Conditions and comments:", size=10, weight="bold")
    page.y += 0.25
    height = min(2.2, page.room - 0.1)
    page.fig.add_artist(Rectangle(
        (MARGIN / PAGE_WIDTH, 1 - (page.y + height) / PAGE_HEIGHT), total / PAGE_WIDTH,
        height / PAGE_HEIGHT, transform=page.fig.transFigure, facecolor="none",
        edgecolor="0.4", lw=0.7))
    page.y += height + 0.1


def _carriage_section(doc, carriage, png, caption):
    """The carriage section of a carriage study on new pages: its paragraphs, its tables
    and the load-distribution figure after table ``figure_after``."""
    doc.new_page()
    doc.heading(carriage["heading"])
    for text in carriage.get("paragraphs", ()):
        doc.paragraph(text, size=8.5)
    for k, table in enumerate(carriage.get("tables", ())):
        doc.heading(table.heading, size=10.5)
        doc.table(list(table.header), [[str(c) for c in row] for row in table.rows],
                  list(table.widths))
        if table.note:
            doc.paragraph(table.note, size=7.5, colour="0.4")
        if k == carriage.get("figure_after") and png is not None:
            doc.image(png, caption)


def _block(doc, item):
    """A sentence (str) or a table with its heading and note (one without rows: heading and
    note only)."""
    if isinstance(item, str):
        doc.paragraph(item, size=8.5)
        return
    doc.heading(item.heading, size=10.5)
    if item.rows:
        doc.table(list(item.header), [[str(c) for c in row] for row in item.rows],
                  list(item.widths))
    if item.note:
        doc.paragraph(item.note, size=7.5, colour="0.4")


def _friction_section(doc, friction, png, caption):
    """The section "What contact costs" of a study with ``[contact]`` where its figure comes:
    its heading, paragraphs and tables, the friction figure after table ``figure_after``,
    and its notes."""
    doc.heading(friction["heading"], size=11.5)
    for text in friction.get("paragraphs", ()):
        doc.paragraph(text, size=8.5)
    for k, table in enumerate(friction.get("tables", ())):
        doc.heading(table.heading, size=10.5)
        doc.table(list(table.header), [[str(c) for c in row] for row in table.rows],
                  list(table.widths))
        if table.note:
            doc.paragraph(table.note, size=7.5, colour="0.4")
        if k == friction.get("figure_after") and png is not None:
            doc.image(png, caption)
    for text in friction.get("notes", ()):
        doc.paragraph(text, size=7.5, colour="0.4")


def write_pdf(path, **report) -> str:
    """Write the PDF report (the pages of :func:`report_pages`).

    Parameters
    ----------
    path : str
        Output file (written through a temporary file and a rename; on an error, a full
        disk say, the temporary file is removed).
    **report
        The arguments of :func:`report_pages`.

    Returns
    -------
    str
        ``path``.
    """
    data = render_pdf(**report)
    tmp = f"{path}.tmp"
    try:
        with open(tmp, "wb") as fh:
            fh.write(data)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return os.fspath(path)


def render_pdf(**report) -> bytes:
    """The PDF report (the pages of :func:`report_pages`, whose arguments ``report`` are)
    as bytes."""
    pages = report_pages(**report)
    metadata = {"Title": report["title"], "Author": "tolsim",
                "Subject": "Monte Carlo tolerance study", "Creator": f"tolsim {__version__}"}
    buf = io.BytesIO()
    with matplotlib.rc_context(RC), PdfPages(buf, metadata=metadata) as pdf:
        for fig in pages:
            pdf.savefig(fig)
    return buf.getvalue()


def report_pages(*, title, subtitle, verdict, headline, facts, tolerances, assumptions,
                 figures, captions, sections, result_path, sign_off, carriage=None,
                 friction=None, glance=(), glance_notes=(), section_tables=None,
                 provenance=(), tolerance_note="", unverified="") -> list:
    """The pages of the PDF report, A4 portrait Figures in order.

    Parameters
    ----------
    title, subtitle : str
        The study and a line naming the result file, tolsim and the date.
    verdict : tolsim.reports.verdict.Verdict
    headline : list of str
        The key sentences (:func:`tolsim.reports.study.headline`).
    facts : list of (str, str)
        What was studied.
    tolerances : list of tolsim.reports.assumptions.ToleranceRow
    assumptions : list of tolsim.reports.assumptions.Assumption
    figures : dict
        name -> PNG bytes, in report order.
    captions : dict
        name -> caption.
    sections : dict
        name -> section heading of the figure.
    result_path : str
        The result file (its SHA-256 goes into the sign-off block).
    sign_off : (roles, fields, decisions)
    carriage : dict, optional
        The section of a carriage study (:func:`tolsim.reports.study.carriage_content`):
        ``heading``, ``paragraphs``, ``tables`` (objects with ``heading``, ``header``,
        ``rows``, ``widths`` and ``note``, :class:`tolsim.reports.study.ReportTable`) and
        ``figure_after``, the table that ``figures["carriage"]`` follows.
    friction : dict, optional
        The section "What contact costs" of a study with ``[contact]``
        (:func:`tolsim.reports.study.friction_content`): ``heading``, ``paragraphs``,
        ``tables``, ``figure_after`` (the table that ``figures["friction"]`` follows) and
        ``notes``; drawn where the friction figure comes.
    tolerance_note : str
        The sentence below the table of sampled inputs.
    glance : list of (str, str)
        The rows of "Results at a glance" (:func:`tolsim.reports.study.shared.glance_rows`),
        drawn after the assumptions; ``glance_notes`` are sentences below them.
    section_tables : dict, optional
        Section name (a key of ``sections``) -> what follows its figure, in order: tables
        (objects like ``carriage``'s; one without rows is its heading and note) and
        sentences (str). A section with these but no figure gets its heading. Sections are
        drawn in the order of ``sections``.
    provenance : list of (str, str)
        The provenance table (global attributes of the result file), before the sign-off
        (the HTML page has it after; the sign-off closes the PDF on its own page).
    unverified : str
        Why the file's checksums were not verified ("" when they were): said under the
        title, at the sign-off and in every page's footer.

    Returns
    -------
    list of matplotlib.figure.Figure
    """
    sha = file_sha256(result_path)
    doc = _Document(title)
    page = doc.page
    page.text(MARGIN, page.y, "tolsim tolerance study report", size=10, color="0.4")
    page.y += 0.25
    for line in wrap(title, PAGE_WIDTH - 2 * MARGIN, 15, "bold"):
        page.text(MARGIN, page.y, line, size=15, weight="bold")
        page.y += 0.3
    doc.paragraph(subtitle, size=8, colour="0.4")
    doc.paragraph(f"Result file SHA-256: {sha}", size=7.5, colour="0.4")
    warning = (f"CHECKSUMS NOT VERIFIED: {unverified}. The numbers of this report may not be "
               "those tolsim wrote: do not sign off on it." if unverified else "")
    if warning:
        doc.paragraph(warning, size=9, colour="#b00020", weight="bold")
    colour = STATUS_COLOURS.get(verdict.status, "#555555")
    doc.box(f"Verdict: {verdict.label}", colour, headline)
    doc.table(["quantity", "requirement", "estimate", "verdict", "why"],
              [[c.quantity, c.requirement, c.estimate, STATUS_LABELS.get(c.status, c.status),
                c.reason] for c in verdict.checks],
              [0.19, 0.13, 0.25, 0.12, 0.31],
              colours=[{3: STATUS_COLOURS.get(c.status, "0.3")} for c in verdict.checks])
    doc.paragraph("Pass: the whole 95 % interval meets the limit; fail: the whole interval "
                  "violates it; undecided: the interval straddles it. Spec limits come from "
                  "the config's [study] section; a quantity without one gets no verdict.",
                  size=7.5, colour="0.4")
    doc.heading("What was studied", size=11.5)
    doc.table(["item", "value"], [list(r) for r in facts], [0.35, 0.65])
    doc.new_page()
    doc.heading("Sampled inputs (tolerances and the initial gap)")
    if tolerances:
        doc.table(["input", "scope", "distribution", "parameters", "config"],
                  [[r.source, r.scope, r.distribution, r.parameters, r.key]
                   for r in tolerances], [0.25, 0.08, 0.15, 0.3, 0.22])
        if tolerance_note:
            doc.paragraph(tolerance_note, size=7.5, colour="0.4")
    else:
        doc.paragraph("The config stored in the result file names no sampled input.")
    doc.heading("Assumptions and where they come from")
    doc.table(["topic", "assumption", "value", "source"],
              [[r.topic, r.item, r.value, r.source] for r in assumptions],
              [0.11, 0.2, 0.38, 0.31])
    if glance:
        doc.heading(sections.get("glance", "Results at a glance"))
        doc.table(["quantity", "value"], [list(r) for r in glance], [0.4, 0.6])
        for text in glance_notes:
            doc.paragraph(text, size=8.5)
    if carriage is not None:
        _carriage_section(doc, carriage, figures.get("carriage"), captions.get("carriage", ""))
    doc.new_page()
    section_tables = section_tables or {}
    names = list(figures) + [n for n in sections if n not in figures and n in section_tables]
    order = [n for n in sections if n in names] + [n for n in names if n not in sections]
    for name in order:
        png = figures.get(name)
        if name == "carriage" and carriage is not None:
            continue  # drawn in its section
        if name == "friction" and friction is not None:
            _friction_section(doc, friction, png, captions.get(name, ""))
        elif png is not None:
            doc.image(png, captions.get(name, ""), heading=sections.get(name, name))
        else:
            doc.heading(sections.get(name, name), size=11.5)
        for item in section_tables.get(name, ()):
            _block(doc, item)
    if provenance:  # before the sign-off, which closes the report on its own page
        doc.heading("Provenance", size=11.5)
        doc.table(["attribute", "value"], [list(r) for r in provenance], [0.3, 0.7])
    doc.new_page()
    if warning:
        doc.paragraph(warning, size=9, colour="#b00020", weight="bold")
    _sign_off(doc, sha, *sign_off)
    doc.finish(f"{title} | tolsim {__version__} | result SHA-256 {sha[:16]}…"
               + (" | checksums NOT verified" if unverified else ""))
    return [p.fig for p in doc.pages]


__all__ = ["file_sha256", "render_pdf", "report_pages", "wrap", "write_pdf"]
