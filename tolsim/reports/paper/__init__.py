"""The source paper reproduced: Fig. 4, Fig. 7, Fig. 9 and Table 2 of [Lin2018] (``tolsim paper``).

:func:`make_paper` computes everything from the models (:mod:`tolsim.study.analyses.paper_data`,
:mod:`tolsim.physics.velocity.analytic`, :mod:`tolsim.study.pipeline.propagation`) and writes

* ``fig4.png``: normalised friction force f_z/(mu F) and spin moment M_O/(mu F R_B) against
  c/a for four conformities, (a) full range, (b) zoom with the fitted k_f;
* ``fig7.png``: epsilon over rho and theta from (a) the full model, (b) the prior point
  model, (c) the analytical formula (Eq. 24 / 26), (d) full minus formula;
* ``fig9.png``: deviation of ball position from v t / 2 for the two balls of Sec. 3.2,
  (a) colliding (contact time marked), (b) mitigated;
* ``after_contact.png``: beyond the paper, labelled as tolsim's extension: the two balls of
  Sec. 3.2 case (a) after they touch (:func:`after_contact_data`), their positions, their
  contact force and the carriage friction force of their track against time, on the path of
  a study with ``[contact]`` (:mod:`tolsim.physics.trains`,
  :mod:`tolsim.study.pipeline.track_friction`);
* ``table2.csv`` and ``table2.md``: Table 2 with the paper's values beside ours;
* ``README.md``: what matches, what does not, by how much and why; every number in it is
  computed at generation time.

The paper's figures are not in its text extraction, so the figures are compared with the
statements of its text and with Table 2, which it prints.

Reference: [Lin2018] B. Lin, C. E. Okwudire, M. Duan, J. S. Wou, IMECE2018-88033.

The package: :mod:`~tolsim.reports.paper.figures` (Table 2 and the figures),
:mod:`~tolsim.reports.paper.readme` (``README.md``) and :mod:`~tolsim.reports.paper.report`
(the driver, :func:`make_paper`).
"""

from tolsim.reports.paper.figures import (
    AFTER_CONTACT_BALL_FRICTION,
    AFTER_CONTACT_SAMPLES,
    AFTER_CONTACT_SOURCES,
    AGREEMENT_REGION,
    FIG9_DURATION,
    FIG9_GAP,
    FORCE_LABELS,
    GRIDS,
    MODEL_LABELS,
    PAPER_COLUMN,
    ROUND_OFF_PERCENT,
    TABLE2_TOLERANCE_PP,
    TIE_TOLERANCE_PP,
    after_contact_data,
    after_contact_summary,
    fig9_data,
    plot_after_contact,
    plot_fig4,
    plot_fig7,
    plot_fig9,
    signed_text,
    table2_checks,
    table2_markdown,
    table2_table,
    without_round_off,
)
from tolsim.reports.paper.readme import (
    fig7_summary,
    locations_text,
    readme_text,
)
from tolsim.reports.paper.report import (
    PaperOutputs,
    make_paper,
)
from tolsim.study.analyses import paper_data

__all__ = [
    "AFTER_CONTACT_BALL_FRICTION", "AFTER_CONTACT_SAMPLES", "AFTER_CONTACT_SOURCES",
    "AGREEMENT_REGION", "FIG9_DURATION", "FIG9_GAP", "FORCE_LABELS", "GRIDS", "MODEL_LABELS",
    "PAPER_COLUMN", "PaperOutputs", "ROUND_OFF_PERCENT", "TABLE2_TOLERANCE_PP",
    "TIE_TOLERANCE_PP", "after_contact_data", "after_contact_summary", "fig7_summary",
    "fig9_data", "locations_text", "make_paper", "paper_data", "plot_after_contact",
    "plot_fig4", "plot_fig7", "plot_fig9", "readme_text", "signed_text", "table2_checks",
    "table2_markdown", "table2_table", "without_round_off",
]
