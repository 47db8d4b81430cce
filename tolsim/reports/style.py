"""One look for every tolsim figure: sizes, fonts, colours, and PNG output through Agg."""

import base64
import functools
import io
import os

import matplotlib
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

#: Resolution of saved PNGs [dots per inch].
DPI = 130
#: Colours of the models, the same in every figure (colour-blind safe, Okabe-Ito).
MODEL_COLOURS = {
    "full": "#0072B2",
    "full-curved": "#56B4E9",
    "analytic": "#009E73",
    "eq24": "#E69F00",
    "formula": "#E69F00",
    "point": "#CC79A7",
    "Leblanc": "#000000",
    "paper": "#000000",
}
#: Line colours for series (balls, conformities, ...).
SERIES_COLOURS = ("#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9",
                  "#F0E442", "#000000")
#: Spec limits, thresholds.
LIMIT_COLOUR = "#D55E00"

RC = {
    "font.size": 10,
    "axes.titlesize": 11,
    "axes.labelsize": 10,
    "legend.fontsize": 9,
    "xtick.labelsize": 9,
    "ytick.labelsize": 9,
    "axes.grid": True,
    "grid.alpha": 0.3,
    "axes.spines.top": False,
    "axes.spines.right": False,
    "figure.constrained_layout.use": True,
    "savefig.dpi": DPI,
}


def styled(func):
    """Run a plotting function inside the house style (``matplotlib.rc_context(RC)``).

    Artists take their defaults from rcParams when they are created, so the whole plotting
    function runs inside the context; the caller's rcParams are untouched afterwards.
    """

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        with matplotlib.rc_context(RC):
            return func(*args, **kwargs)

    return wrapper


def new_canvas(width=6.4, height=4.2):
    """A Figure without axes on an Agg canvas (constrained layout), for grid layouts and
    text pages. Call it from a function decorated with :func:`styled`."""
    fig = Figure(figsize=(width, height), layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def new_figure(width=6.4, height=4.2, **subplots):
    """A Figure on an Agg canvas and its axes (``Figure.subplots(**subplots)``).

    Call it from a function decorated with :func:`styled`.

    Returns
    -------
    fig, axes
    """
    fig = new_canvas(width, height)
    return fig, fig.subplots(**subplots)


def render_png(fig, dpi=DPI) -> bytes:
    """The figure as PNG bytes (Agg) at ``dpi`` [dots per inch]."""
    buf = io.BytesIO()
    with matplotlib.rc_context(RC):
        fig.savefig(buf, format="png", dpi=dpi)
    return buf.getvalue()


def save_png(fig, path) -> str:
    """Write ``fig`` to ``path`` (PNG, through a temporary file and a rename: on an error, a
    full disk say, nothing is left half-written) and return the path."""
    data = render_png(fig)
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


def data_uri(png: bytes) -> str:
    """A ``data:image/png;base64,...`` URI for embedding in HTML."""
    return "data:image/png;base64," + base64.b64encode(png).decode("ascii")
